"""Ground-truth scenes: analytic spheres, boxes and a ground plane rendered by exact ray intersection.

Why: geometry metrics (Chamfer distance of an exported mesh), tests, benchmarks and ``fourierf-synth`` need a
scene whose answer is known exactly and that needs no download. The output is a NeRF-synthetic ("Blender")
dataset, so the ordinary Blender parser reads it, with the analytic geometry saved beside it as
``geometry.json``. Training never imports this package.

One module per job: ``primitives`` (shapes and their exact ray hits), ``scene`` (a scene and its JSON),
``cameras`` (viewpoints and pixel rays), ``render`` (ray casting to RGBA), ``dataset`` (the Blender-format
writer) and ``surface`` (the true surface that meshes are scored against).
"""

from fourierf_plugin.synthetic.cameras import split_cameras
from fourierf_plugin.synthetic.dataset import write_blender_dataset
from fourierf_plugin.synthetic.primitives import Box, GroundPlane, Sphere
from fourierf_plugin.synthetic.render import intersect_scene, render_view
from fourierf_plugin.synthetic.scene import SceneSpec, default_scene, load_scene, save_scene
from fourierf_plugin.synthetic.surface import sample_surface, surface_distance

__all__ = [
    "Box",
    "GroundPlane",
    "SceneSpec",
    "Sphere",
    "default_scene",
    "intersect_scene",
    "load_scene",
    "render_view",
    "sample_surface",
    "save_scene",
    "split_cameras",
    "surface_distance",
    "write_blender_dataset",
]
