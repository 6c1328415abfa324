"""The job: files in, files out, around one per-frame step.

``options``     what a run is asked (:class:`JobOptions`), what it returns, the parsers
``frames``      which frames, from which files to which, at what time
``checkpoint``  the state after every frame, resume, stale temporaries
``setup``       what a run decides once (colour, display, calibration)
``frame``       the per-frame step every entry shares: :func:`frame_input`,
                :func:`map_frame`, the output's metadata and encoding
``stream``      a frame too large to hold whole, in row bands
``run``         the main job over an image or a sequence (:func:`run_job`)
``simulate``    one still seen over time
``imagebuf``    the ImageBuf API

This package's ``__init__`` imports nothing, so ``pipeline`` can reach
``job.imagebuf`` (below it) without loading ``job.run`` (above it).
"""
