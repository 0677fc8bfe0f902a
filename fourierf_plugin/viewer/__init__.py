"""The web viewer: renders of a run at any camera and Fourier cutoff, served through viser.

- ``render_service``: a camera and a pair of cutoffs -> RGB / depth / accumulation pictures (pure; no viser).
- ``render_budget``: the cap on the share of wall time renders may take (the live viewer's slowdown promise).
- ``viewed_run``: the model being shown, its step and a lock shared by the render thread and mesh exports.
- ``scene_view``: the training cameras (with images) and the test cameras as frustums, the world up, the start view.
- ``server``: the viser server, its controls and the background render thread.
- ``live``: the training observer (``--viewer True``) that feeds the page snapshots of the parameters.

``fourierf-viewer`` (``scripts/viewer.py``) serves a saved run. viser is the optional ``[viewer]`` extra; it is
imported only when a page is opened.
"""
