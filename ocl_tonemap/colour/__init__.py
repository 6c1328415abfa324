"""Colour management through OpenColorIO, in three rooms:

``config``     which config, which colourspace a file is in, displays and views
``processor``  the frame's colour pipeline (:class:`ColourPipeline`)
``table``      the display transform baked into tables for the device
``lut_files``  every file a processor reads, checked before OCIO opens it

The names below are this package's public face (``from ocl_tonemap.colour import ...``).
"""

from __future__ import annotations

from .config import (  # noqa: F401
    BRADFORD, BUNDLED_NAMES, ColourError, InputColour, PLAIN_VIEWS,
    REC709_CHROMATICITIES, USE_DISPLAY_NAME, WORKING_CANDIDATES, apply_processor,
    builtin_config, bundled_config_path, chromaticities_to_working,
    chromaticities_to_xyz, default_display, default_view, input_colorspace, interop_id,
    is_builtin_source, is_rec709, list_displays, load_config, resolve_config_source,
    resolve_input, working_space, xyz_to_chromaticities)
from .table import (  # noqa: F401
    CODE_10BIT, DISPLAY_ENCODE_MODES, DisplayTable, NODES_PER_OCTAVE_1D, SHAPER_EPS_1D,
    SHAPER_EPS_3D, bake_display_table, cached_display_table, display_probe_set, shaper,
    shaper_inverse)
from .lut_files import LUT_CAP, LutFileError, check_lut_files  # noqa: F401
from .processor import (  # noqa: F401
    ColourPipeline)
