"""The base layer: what every other layer may use, and nothing of theirs.

``resources.py``   package data folders, the user cache, memory and disk at hand;
``interrupts.py``  SIGINT/SIGTERM: one line, an exit code, a watchdog for blocked calls;
``safeio.py``      safe writes: no links followed, temporaries made exclusively, fsync;
``quantities.py``  every number a user gives, declared once with its unit and range;
``reuse.py``       values kept while their inputs stay the same.
"""
