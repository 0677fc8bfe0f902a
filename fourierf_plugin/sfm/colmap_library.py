"""``pycolmap``, imported only when structure-from-motion runs, with one clear error naming the extra when missing."""

from __future__ import annotations

from types import ModuleType

from fourierf_plugin.utils.errors import fail

INSTALL_FIX = "install the optional extra: pip install '.[colmap]' (or: pip install 'fourierf[colmap]')"


def import_pycolmap(verbose: bool = False) -> ModuleType:
    """The ``pycolmap`` module, with COLMAP's own log lines off unless ``verbose`` (they would break the display).

    ``zlib`` is loaded first: pycolmap's library carries zlib functions of its own, and once it is loaded before the
    system zlib, every later compression in the process (PNG writing included) corrupts the heap and aborts.
    """
    import zlib  # noqa: F401  (load order only: see above)

    try:
        import pycolmap
    except ImportError as err:
        fail(
            f"structure-from-motion needs pycolmap (COLMAP in Python), which is not installed ({err})",
            INSTALL_FIX,
        )
    pycolmap.logging.minloglevel = 0 if verbose else 2  # glog: 0 info, 1 warning, 2 error
    return pycolmap
