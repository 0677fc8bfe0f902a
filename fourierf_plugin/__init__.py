"""fourierf: FourieRF few-shot radiance fields as a self-contained nerfstudio-style plugin."""

__version__ = "0.2.0"
