"""How the viewer's page is opened without a screen (the browser test and the latency benchmark): Debian's chromium.

Why these flags: on a machine with a closed network chromium's background connections fail by the dozen unless they
are turned off, and the page draws its scene with WebGL, which a GPU-less machine has only in software (SwiftShader).
"""

from __future__ import annotations

from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS: tuple[str, ...] = (
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)
