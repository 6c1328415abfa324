"""OpenCL drivers: the device probe, its cache, broken drivers skipped and explained,
the reference fallback, exit codes, Intel's CPU runtime registered for the ICD loader,
and the ``requires_opencl`` marker.

A broken driver is made on any machine with PoCL's own switch: ``POCL_EXTRA_BUILD_FLAGS=
-bogus-flag`` fails every PoCL kernel build (with fresh PoCL and pyopencl caches, so no
cached binary hides it). ``OCL_ICD_VENDORS`` at an empty folder hides every driver but
the PoCL in pyopencl's own folder, so these runs see that one device, broken, whatever
else the machine has.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ocl_tonemap.backends.opencl import icd, probe, runtime

HERE = Path(__file__).resolve().parent


def bundled_pocl():
    """pyopencl's bundled PoCL library, or None."""
    import pyopencl
    libs = Path(pyopencl.__file__).parent / ".libs"
    found = sorted(libs.glob("libpocl*.so*")) if libs.is_dir() else []
    return found[0] if found else None


needs_pocl = pytest.mark.skipif(bundled_pocl() is None,
                                reason="pocl-binary-distribution is not installed")


def broken_env(tmp_path, **extra):
    """The environment of a run whose only OpenCL device is the bundled PoCL, broken."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYOPENCL_CTX", "OCL_ICD_VENDORS", "OPENCL_VENDOR_PATH")}
    (tmp_path / "vendors").mkdir(exist_ok=True)
    (tmp_path / "pocl-cache").mkdir(exist_ok=True)
    env.update(POCL_EXTRA_BUILD_FLAGS="-bogus-flag", PYOPENCL_NO_CACHE="1",
               POCL_CACHE_DIR=str(tmp_path / "pocl-cache"),
               OCLTM_CACHE_DIR=str(tmp_path / "cache"),
               OCL_ICD_VENDORS=str(tmp_path / "vendors"))
    env.update(extra)
    return env


def cli(args, env, cwd):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.fixture(scope="module")
def one_frame(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("drv")
    pattern, frames = write_tunnel_sequence(str(d), 32, 18, 30.0, 0.1)
    return pattern.replace("####", f"{frames[0]:04d}")


# --- the probe and its cache ----------------------------------------------------------

@pytest.mark.requires_opencl
def test_probe_passes_and_is_cached(rt, tmp_path, monkeypatch):
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(probe, "_verdicts", {})
    v = probe.verdict(rt.device)
    assert v.ok and not v.cached and v.seconds > 0, v
    doc = json.loads((tmp_path / "probe.json").read_text())
    rec = doc[probe.cache_key(rt.device)]
    assert rec["ok"] is True and rec["driver_version"] == rt.device.driver_version.strip()
    monkeypatch.setattr(probe, "_verdicts", {})
    warm = probe.verdict(rt.device)          # a new process: from the file, no build
    assert warm.ok and warm.cached and warm.seconds == 0


@pytest.mark.requires_opencl
def test_driver_change_invalidates_the_cached_verdict(rt, tmp_path, monkeypatch):
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(probe, "_verdicts", {})
    key = probe.cache_key(rt.device)
    probe._store(key, {"ok": False, "reason": "recorded for the old driver"})
    assert probe.verdict(rt.device) == probe.Verdict(False, "recorded for the old driver",
                                                     cached=True)
    # the driver updated: the same device now reports another driver version
    record = probe.device_record
    monkeypatch.setattr(probe, "device_record", lambda d: {
        **record(d), "driver_version": record(d)["driver_version"] + "-next"})
    assert probe.cache_key(rt.device) != key
    v = probe.verdict(rt.device)             # probed again, and it works
    assert v.ok and not v.cached
    monkeypatch.setattr(probe, "device_record", record)
    # a project version change is a new key as well
    from ocl_tonemap import version
    monkeypatch.setattr(version, "__version__", version.__version__ + ".post1")
    assert probe.cache_key(rt.device) != key


def test_first_error_line_of_real_messages():
    pocl = ("clBuildProgram failed: BUILD_PROGRAM_FAILURE - clBuildProgram failed: "
            "BUILD_PROGRAM_FAILURE\n\nBuild on <pyopencl.Device 'pthread-AMD Ryzen 9 9950X' on "
            "'Portable Computing Language' at 0x1>:\n\nerror: unknown target CPU 'generic'\n"
            "note: valid target CPU values are: nocona, core2\n(options: -I /x)")
    assert probe.first_error_line(pocl) == "error: unknown target CPU 'generic'"
    assert probe.first_error_line("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR") == \
        "clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR"


# --- a broken driver, end to end --------------------------------------------------------

@needs_pocl
def test_devices_marks_the_broken_device(tmp_path):
    env = broken_env(tmp_path)
    r = cli(["devices"], env, tmp_path)
    assert r.returncode == 0, r.stderr
    out = lines(r.stdout)
    assert any("Portable Computing Language" in ln and
               ln.endswith("broken: Invalid build option: -bogus-flag") for ln in out), out
    assert "no working device" in out[-1] and "fix: " in out[-1]
    if icd.intel_library() is None:         # the fix names Intel's runtime where absent
        assert "pip install intel-opencl-rt intel-cmplr-lib-rt" in out[-1]
    assert cli(["devices", "--check"], env, tmp_path).returncode == 1
    assert "Traceback" not in r.stderr
    # the verdict is cached, keyed with the PoCL setting that broke it
    doc = json.loads((tmp_path / "cache" / "probe.json").read_text())
    assert [rec["ok"] for rec in doc.values()] == [False]


@needs_pocl
def test_run_falls_back_to_the_reference_with_one_warning(tmp_path, one_frame):
    env = broken_env(tmp_path)
    out = tmp_path / "o.exr"
    r = cli(["run", one_frame, str(out), "--out-bits", "float"], env, tmp_path)
    assert r.returncode == 0, r.stderr
    err = lines(r.stderr)
    assert len(err) == 1 and err[0].startswith("ocl-tonemap WARNING: no working OpenCL device"), err
    assert "reference backend" in err[0] and "slower" in err[0] and "fix: " in err[0]
    # the frames are the reference backend's, as --backend reference makes them
    ref = tmp_path / "ref.exr"
    r2 = cli(["run", one_frame, str(ref), "--out-bits", "float", "--backend", "reference"],
             env, tmp_path)
    assert r2.returncode == 0 and not lines(r2.stderr), r2.stderr
    import OpenImageIO as oiio
    a, b = (oiio.ImageBuf(str(p)).get_pixels(oiio.FLOAT) for p in (out, ref))
    assert np.isfinite(a).all() and np.array_equal(a, b)


@needs_pocl
@pytest.mark.parametrize("args", [["--backend", "opencl"], ["--device", "0:0"],
                                  ["--device", "pocl", "--backend", "opencl"]])
def test_explicit_opencl_on_a_broken_device_is_one_error_line(tmp_path, one_frame, args):
    r = cli(["run", one_frame, str(tmp_path / "o.png"), *args], broken_env(tmp_path), tmp_path)
    assert r.returncode == 2
    err = lines(r.stderr)
    assert len(err) == 1 and err[0].startswith("ocl-tonemap ERROR: "), err
    assert "-bogus-flag" in err[0] and "fix:" in err[0]
    assert not (tmp_path / "o.png").exists()


@needs_pocl
def test_demo_and_simulate_make_frames_with_one_warning(tmp_path, one_frame):
    env = broken_env(tmp_path)
    r = cli(["demo", str(tmp_path / "demo"), "--seconds", "0.2", "--size", "32x18"], env,
            tmp_path)
    assert r.returncode == 0, r.stderr
    assert len(lines(r.stderr)) == 1 and "WARNING" in r.stderr
    assert len(list((tmp_path / "demo" / "display").glob("*.png"))) == 6
    r = cli(["simulate", one_frame, str(tmp_path / "s.png"), "--at", "1,60",
             "--preadapt", "1000"], env, tmp_path)
    assert r.returncode == 0, r.stderr
    assert len(lines(r.stderr)) == 1 and "WARNING" in r.stderr
    assert (tmp_path / "s_t0001s.png").is_file() and (tmp_path / "s_t0060s.png").is_file()


@needs_pocl
def test_a_kernel_failing_after_the_probe_passed_is_one_error_line(tmp_path, one_frame):
    """The probe's verdict said ok (cached before the driver broke); the first real
    program then fails to build: one ERROR line naming the kernel file, and the stale
    verdict is forgotten so that the next start probes again."""
    env = broken_env(tmp_path)
    seed = ("from ocl_tonemap.backends.opencl import probe, runtime\n"
            "d = runtime.list_devices()[0][1]\n"
            "probe._store(probe.cache_key(d), {'ok': True, 'reason': ''})\n")
    subprocess.run([sys.executable, "-c", seed], env=env, check=True, timeout=120)
    r = cli(["run", one_frame, str(tmp_path / "o.png")], env, tmp_path)
    assert r.returncode == 2
    err = lines(r.stderr)
    assert len(err) == 1 and err[0].startswith("ocl-tonemap ERROR: OpenCL kernel build "
                                               "failed: kernels/"), err
    assert ".cl on 'pthread" in err[0] and "-bogus-flag" in err[0]
    assert json.loads((tmp_path / "cache" / "probe.json").read_text()) == {}
    r = cli(["run", one_frame, str(tmp_path / "o.png")], env, tmp_path)
    assert r.returncode == 0 and "reference backend" in r.stderr


# --- Intel's CPU runtime registered for the loader ----------------------------------------

@needs_pocl
def test_vendors_folder_keeps_the_system_icds(tmp_path, monkeypatch):
    """The merged folder links every system .icd and adds ours; the loader reads both
    through it (here both name the bundled PoCL library, so it is listed three times:
    pyopencl's own folder, the system's link, ours)."""
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path / "cache"))
    system = tmp_path / "etc-vendors"
    system.mkdir()
    (system / "vendor-gpu.icd").write_text(f"{bundled_pocl()}\n")
    lib = tmp_path / "lib" / "libintelocl.so"
    lib.parent.mkdir()
    shutil.copy(bundled_pocl(), lib)
    folder = icd.vendors_folder(lib, [system / "vendor-gpu.icd"])
    assert sorted(p.name for p in folder.iterdir()) == [icd.INTEL_ICD, "vendor-gpu.icd"]
    assert (folder / "vendor-gpu.icd").resolve() == (system / "vendor-gpu.icd").resolve()
    assert icd.vendors_folder(lib, [system / "vendor-gpu.icd"]) == folder   # made once
    count = ("import pyopencl as cl\n"
             "print(sum(len(p.get_devices()) for p in cl.get_platforms()))\n")
    env = {**os.environ, "OCL_ICD_VENDORS": str(folder), "PYOPENCL_NO_CACHE": "1"}
    r = subprocess.run([sys.executable, "-c", count], env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.stdout.strip() == "3", r.stdout + r.stderr
    # a library the system registers already needs no folder
    (system / "intel.icd").write_text(f"{lib}\n")
    assert icd.vendors_folder(lib, sorted(system.iterdir())) is None


@pytest.mark.skipif(icd.intel_library() is None, reason="the intel-cpu extra is not installed")
def test_intel_runtime_registered_beside_a_system_icd(tmp_path):
    """With the intel-cpu extra: Intel's device is listed with no OCL_ICD_VENDORS from
    the user, and a system ICD stays listed beside it."""
    system = tmp_path / "etc-vendors"
    system.mkdir()
    if bundled_pocl() is not None:
        (system / "system-pocl.icd").write_text(f"{bundled_pocl()}\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OCL_ICD_VENDORS",
                                                           "OPENCL_VENDOR_PATH")}
    env.update(OCLTM_CACHE_DIR=str(tmp_path / "cache"), OCLTM_SYSTEM_ICD_DIR=str(system))
    r = cli(["devices"], env, tmp_path)
    assert r.returncode == 0, r.stderr
    names = [ln for ln in lines(r.stdout) if ln[:1].isdigit()]
    assert any("Intel(R) OpenCL" in ln for ln in names), names
    if bundled_pocl() is not None:          # pyopencl's own PoCL and the system's link
        assert sum("Portable Computing Language" in ln for ln in names) == 2, names


# --- the requires_opencl marker -------------------------------------------------------------

@needs_pocl
@pytest.mark.parametrize("ci", ["true", ""])
def test_requires_opencl_fails_in_ci_and_skips_elsewhere(tmp_path, ci):
    shutil.copy(HERE.parent / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_x.py").write_text(textwrap.dedent("""
        import pytest

        @pytest.mark.requires_opencl
        def test_needs_a_device():
            pass

        def test_plain():
            pass
        """))
    env = broken_env(tmp_path, CI=ci)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider",
                        str(tmp_path)], env=env, cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert "OpenCL: no working device" in r.stdout      # the summary line, under -q too
    msg = "requires_opencl: no working OpenCL device"
    if ci:      # fails at set-up: an error, which fails the run
        assert r.returncode == 1 and "1 passed, 1 error" in r.stdout, r.stdout
    else:
        assert r.returncode == 0 and "1 passed, 1 skipped" in r.stdout, r.stdout
    assert msg in r.stdout and "-bogus-flag" in r.stdout


def test_the_compilers_chatter_is_dropped_and_a_slow_build_says_so_once(capfd):
    """While a program builds, standard error (descriptor 2, where PoCL's clang prints
    "5 warnings generated." and its diagnostics) is taken aside: the compiler's lines
    are dropped, another thread's are written back after; a build still going after
    its delay says the notice once, on the real standard error, at that moment."""
    import os
    import threading
    from ocl_tonemap.backends.opencl.driver import quiet_compiler
    said, spoken = [], threading.Event()

    def notice():
        said.append(1)
        spoken.set()
        return "ocl-tonemap NOTE: building\n"
    with quiet_compiler(notice, 0.01):
        os.write(2, b"5 warnings generated.\n")
        os.write(2, b"input.cl:12:3: warning: unused variable 'x'\n")
        os.write(2, b"   12 |   float x;\n")
        writer = threading.Thread(target=lambda: os.write(2, b"ocl-tonemap WARNING: a reader\n"))
        writer.start()
        writer.join()
        spoken.wait()                 # a build still going after its delay (no deadline)
    err = capfd.readouterr().err
    assert "warnings generated" not in err and "unused variable" not in err and "12 |" not in err
    assert "ocl-tonemap WARNING: a reader" in err
    assert err.count("ocl-tonemap NOTE: building") == 1
    with quiet_compiler(notice, 3600.0):          # a build done before its delay: no notice
        os.write(2, b"1 warning generated.\n")
    assert capfd.readouterr().err == "" and len(said) == 1
