"""Every fast path of fourierf, behind the field's ``GridOps`` interface (``fields.grid_ops``).

Nothing here changes what the method computes: each piece is the reference operation in a faster form, and
``tests/accel`` compares each with it. ``build_ops`` picks the implementation once, from ``AccelConfig``.
"""

from fourierf_plugin.accel.config import AccelConfig
from fourierf_plugin.accel.ops import AcceleratedOps, build_ops

__all__ = ["AccelConfig", "AcceleratedOps", "build_ops"]
