"""Ground-truth scenes: analytic spheres, boxes, a ground plane and wall panels rendered by exact ray intersection.

Why: geometry metrics (Chamfer distance of an exported mesh), tests, benchmarks and ``fourierf-synth`` need a
scene whose answer is known exactly and that needs no download. The output is a NeRF-synthetic ("Blender")
dataset, so the ordinary Blender parser reads it, with the analytic geometry saved beside it as
``geometry.json``. Training never imports this package.

One module per job: ``primitives`` (shapes and their exact ray hits), ``textures`` (procedural surface patterns),
``scene`` (a scene and its JSON), ``cameras`` (viewpoints and pixel rays), ``render`` (ray casting to RGBA),
``dataset`` (the Blender-format writer), ``nerfstudio_capture`` (the same scenes as a photo capture, through a lens),
``room`` (a textured object in a textured room over a partial arc, with depth and the object's surface) and
``surface`` (the true surface that meshes are scored against).
"""

from fourierf_plugin.synthetic.cameras import split_cameras
from fourierf_plugin.synthetic.dataset import write_blender_dataset
from fourierf_plugin.synthetic.primitives import Box, GroundPlane, Panel, Sphere, room_panels
from fourierf_plugin.synthetic.render import intersect_scene, render_view
from fourierf_plugin.synthetic.room import room_scene, write_room_capture
from fourierf_plugin.synthetic.scene import SceneSpec, default_scene, load_scene, save_scene
from fourierf_plugin.synthetic.surface import sample_surface, surface_distance
from fourierf_plugin.synthetic.textures import Texture

__all__ = [
    "Box",
    "GroundPlane",
    "Panel",
    "SceneSpec",
    "Sphere",
    "Texture",
    "default_scene",
    "intersect_scene",
    "load_scene",
    "render_view",
    "room_panels",
    "room_scene",
    "sample_surface",
    "save_scene",
    "split_cameras",
    "surface_distance",
    "write_blender_dataset",
    "write_room_capture",
]
