"""Dask over TLS and Dask's errors on the command line: a real TLS scheduler and worker
on 127.0.0.1 with certificates this test makes (``cryptography``), reached with
``--scheduler tls://... --scheduler-security FILE``; without certificates, and with a
frame that cannot be read, one ERROR line naming what failed."""

import datetime
import ipaddress
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.io.patterns import frame_path

pytest.importorskip("distributed")
x509 = pytest.importorskip("cryptography.x509")


def _cli(args, timeout=600):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=timeout)
    return p.returncode, p.stderr


def _make_certs(d):
    """A CA and one certificate it signs for localhost / 127.0.0.1 (PEM files)."""
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    now = datetime.datetime.now(datetime.timezone.utc)

    def name(cn):
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = (x509.CertificateBuilder().subject_name(name("ocltm test CA")).issuer_name(name("ocltm test CA"))
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now - datetime.timedelta(minutes=5))
          .not_valid_after(now + datetime.timedelta(days=1))
          .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
          .sign(ca_key, hashes.SHA256()))
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder().subject_name(name("localhost")).issuer_name(ca.subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.SubjectAlternativeName([
                x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                critical=False)
            .sign(ca_key, hashes.SHA256()))
    pem = serialization.Encoding.PEM
    (d / "ca.pem").write_bytes(ca.public_bytes(pem))
    (d / "cert.pem").write_bytes(cert.public_bytes(pem))
    (d / "key.pem").write_bytes(key.private_bytes(pem, serialization.PrivateFormat.PKCS8,
                                                  serialization.NoEncryption()))
    (d / "security.yaml").write_text("ca: ca.pem\ncert: cert.pem\nkey: key.pem\n")
    return ["--tls-ca-file", str(d / "ca.pem"), "--tls-cert", str(d / "cert.pem"),
            "--tls-key", str(d / "key.pem")]


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("tls")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 32, 18, 30.0, 0.3)
    return d, pattern, frames


@pytest.fixture(scope="module")
def tls_cluster(shot):
    """A Dask scheduler and one worker on tls://127.0.0.1 (subprocesses)."""
    d = shot[0] / "certs"
    d.mkdir()
    tls = _make_certs(d)
    dask = shutil.which("dask", path=os.path.dirname(sys.executable))
    if dask is None:
        pytest.skip("the dask command is not installed")
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__DAEMON="False")
    sched = subprocess.Popen([dask, "scheduler", "--host", "tls://127.0.0.1", "--port", "0",
                              "--no-dashboard", "--no-show", *tls],
                             stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env)
    addr, seen = None, []
    while addr is None:                  # its start-up lines, however slow (no deadline)
        line = sched.stderr.readline()
        if not line:                     # it ended
            break
        seen.append(line)
        m = re.search(r"Scheduler at:\s+(tls://[0-9.]+:\d+)", line)
        if m:
            addr = m.group(1)
    if addr is None:
        sched.kill()
        pytest.fail("the TLS scheduler did not start: " + "".join(seen[-10:]))
    worker = subprocess.Popen([dask, "worker", addr, "--nworkers", "1", "--nthreads", "1",
                               "--no-dashboard", *tls], stderr=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL, env=env)
    yield addr, d / "security.yaml"
    for p in (worker, sched):
        p.terminate()
    for p in (worker, sched):
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()


@pytest.mark.requires_opencl
def test_a_shot_on_a_tls_scheduler_equals_the_serial_run(shot, tls_cluster, tmp_path):
    d, pattern, frames = shot
    addr, sec = tls_cluster
    ser = tmp_path / "serial" / "o.####.exr"
    rc, err = _cli(["run", pattern, str(ser), "-q", "--no-checkpoint"])
    assert rc == 0, err
    out = tmp_path / "tls" / "o.####.exr"
    rc, err = _cli(["run", pattern, str(out), "-q", "--scheduler", addr,
                    "--scheduler-security", str(sec), "--store", str(tmp_path / "store")])
    assert rc == 0, err
    for f in frames:
        a = oiio.ImageBuf(frame_path(str(ser), f)).get_pixels(oiio.FLOAT)
        b = oiio.ImageBuf(frame_path(str(out), f)).get_pixels(oiio.FLOAT)
        np.testing.assert_array_equal(a, b)


def test_tls_without_certificates_is_one_line(shot, tmp_path):
    _, pattern, _ = shot
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.exr"), "-q", "--scheduler",
                    "tls://127.0.0.1:1"])
    assert rc == 2 and "Traceback" not in err, err
    assert len([ln for ln in err.splitlines() if "ERROR" in ln]) == 1
    assert "--scheduler-security" in err


def test_a_bad_security_file_is_one_line(shot, tmp_path):
    _, pattern, _ = shot
    (tmp_path / "sec.yaml").write_text("ca: [1, 2]\n")
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.exr"), "-q", "--scheduler",
                    "tls://127.0.0.1:1", "--scheduler-security", str(tmp_path / "sec.yaml")])
    assert rc == 2 and "Traceback" not in err and "--scheduler-security" in err, err


@pytest.mark.requires_opencl
def test_a_failing_frame_on_dask_is_one_line_naming_frame_and_worker(shot, tmp_path):
    d, pattern, frames = shot
    bad = tmp_path / "bad"
    shutil.copytree(os.path.dirname(pattern), bad)
    victim = bad / os.path.basename(frame_path(pattern, frames[3]))
    victim.write_bytes(b"not an image")
    rc, err = _cli(["run", str(bad / os.path.basename(pattern)), str(tmp_path / "o.####.exr"),
                    "-q", "--scheduler", "dask", "--workers", "1"])
    assert rc == 2 and "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if "ERROR" in ln]      # (a driver's warning may
    assert len(lines) == 1, err                                     # precede it)
    assert f"frame {frames[3]}" in lines[0] and "worker" in lines[0] and str(victim) in lines[0]
    assert not [ln for ln in err.splitlines() if ln.strip() and "ERROR" not in ln
                and "WARNING" not in ln], err
