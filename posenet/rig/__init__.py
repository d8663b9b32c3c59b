"""Camera rigs: import and export in the formats users already have, and checks (``python -m posenet.rig``).

- ``rigfile.py``: :class:`Rig` and ``rig.json`` (the ``camera`` objects of ``POST /scenes``);
- ``formats.py``: MVOR, OpenCV/EasyMocap YAML, 4D-OR and plain-JSON readers and writers;
- ``geometry.py``: camera spacing (units) and where the cameras look (transform directions);
- ``check.py`` and ``picture.py``: sanity checks, depth agreement between views, the frusta picture.

All camera conventions are ``posenet.cameras``'s (mm, OpenCV axes, T(v->ref)).
"""

from posenet.rig.rigfile import Rig, read_rig_json, rig_difference, write_rig_json

__all__ = ["Rig", "read_rig_json", "rig_difference", "write_rig_json"]
