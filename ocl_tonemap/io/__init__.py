"""Files to frames and back (the colour and I/O layer, beside ``colour/``).

``imageio.py``      reads through OIIO (channels by ``channels.py``, Radiance headers by
                    ``radiance.py``), the formats and depths;
``imagewrite.py``   verified writes: a temporary, read back, fsync, renamed; the tags;
``patterns.py``     frame-number patterns (``shot.####.exr``);
``state_files.py``  adaptation state files and per-pixel state planes;
``sample.py``       the built-in sample scene;
``plot.py``         the adaptation plot.
"""
