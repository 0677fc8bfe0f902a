"""Density marching cubes: sample a trained field on a vertex grid, extract the iso-surface, write PLY/OBJ/GLB.

Why these pieces are separate pure functions: ``sample_grid`` + ``extract_mesh`` are checked against analytic
densities (a sphere, a box) without any model, and the same ``export_field_mesh`` serves ``fourierf-export`` and the
trainer's ``--export-mesh-at``. Every check a user can fail (suffix, box, resolution, cutoff, level) runs BEFORE the
grid is sampled, so a typo never costs a 512³ evaluation.

Iso-level semantics (``level_kind``):

* ``density``: the level is a volume density σ.
* ``opacity``: the level is the alpha a ray sample of the model sees, α = 1 − exp(−σ·δ·distance_scale) with δ the
  model's step size, i.e. the quantity composited along rays (TensoRF's alpha with its distance scale). In NDC
  scenes the samples are spaced per ray, so δ (the box step in NDC units) makes this an approximation there.

``level="auto"`` picks the surface that makes the object one solid piece: of the opacities 0.5, 0.3, 0.2, 0.1, 0.05,
0.02 and 0.01 (in either kind, for ``density`` the equivalent σ), the highest at which the largest connected piece of
the grid above the level holds at least 95 % of it (``solid_level``; else the level where it holds the most). Why:
the half-opaque surface (α = 0.5 per ray sample) cuts a few-shot field into hundreds of blobs (the bundled lego:
the largest piece held 21 % at 0.5, 98 % at 0.2), while a level a little lower gives the object the renders show.
Pieces smaller than 1 % of the largest are then dropped (``min_component_faces`` None). The report says which level
was used and why. A field that never reaches an explicit level is reported, not silently re-levelled.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
import trimesh
from scipy import ndimage
from skimage.measure import marching_cubes
from torch import Tensor

from fourierf_plugin.exporter.frames import NDC_NOTE, MeshFrame, Space, field_frame, map_mesh
from fourierf_plugin.model_components.rendering import opacity_from_density
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.memory import available_memory, check_fits
from fourierf_plugin.utils.os_errors import user_error_for

LevelKind = Literal["density", "opacity"]
Level = Literal["auto"] | float

SUPPORTED_SUFFIXES = (".ply", ".obj", ".glb")
MIN_RESOLUTION = 2
MAX_RESOLUTION = 1024
AUTO_OPACITIES = (0.5, 0.3, 0.2, 0.1, 0.05, 0.02, 0.01)
"""The opacities ``--level auto`` tries, highest first (see the module docstring)."""
SOLID_SHARE = 0.95
"""The share of the above-level grid the largest connected piece must hold for a level to count as solid."""
SMALL_PIECE = 0.01
"""By default, pieces with fewer faces than this share of the largest piece's are dropped."""
DEFAULT_CHUNK = 2**18
BYTES_PER_VERTEX = 12
"""An estimate of the export's memory per grid vertex: the float32 volume and marching cubes' own arrays."""
__all__ = ["NDC_NOTE", "MeshReport", "export_field_mesh"]


@dataclass
class MeshReport:
    """What an export produced (printed by the CLI, logged by the trainer)."""

    path: Path | None
    vertices: int
    faces: int
    bounds: tuple[tuple[float, float, float], tuple[float, float, float]]
    watertight: bool
    components: int
    """Connected pieces in the written mesh."""
    removed_components: int
    """Pieces dropped by ``min_component_faces`` / ``keep_largest``."""
    level: float
    level_reason: str
    """Why this level: as given, or how ``--level auto`` chose it."""
    level_kind: LevelKind
    field_range: tuple[float, float]
    """Min and max of the sampled field (in ``level_kind`` units)."""
    resolution: tuple[int, int, int]
    bbox: tuple[tuple[float, float, float], tuple[float, float, float]]
    space: Space
    """The coordinates of the written vertices: capture, normalised, ndc or contracted (``bbox`` and ``level`` are
    always the field's own)."""
    frame_note: str
    """One line that says which frame the mesh is in and why."""
    dropped_far_faces: int
    step: int
    frequency_cap: float | None
    seconds: float
    sample_seconds: float

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["path"] = None if self.path is None else str(self.path)
        return out


# ----------------------------------------------------------------------------------------------------- validation
def check_suffix(path: Path) -> str:
    """The mesh format from ``path``'s suffix (``ply``, ``obj`` or ``glb``)."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        fail(
            f"--output-path {path}: unsupported mesh format {suffix or '(no suffix)'!r}",
            f"end the path with one of {', '.join(SUPPORTED_SUFFIXES)}",
        )
    return suffix[1:]


def check_resolution(resolution: int | Sequence[int]) -> tuple[int, int, int]:
    """Vertices per axis; an int applies to all three axes."""
    values = [resolution] * 3 if isinstance(resolution, (int, np.integer)) else list(resolution)
    if len(values) != 3 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in values):
        fail(f"--resolution {resolution!r} must be one integer or three", "e.g. --resolution 256")
    for v in values:
        if v < MIN_RESOLUTION or v > MAX_RESOLUTION:
            fail(
                f"--resolution {resolution!r} is outside [{MIN_RESOLUTION}, {MAX_RESOLUTION}] vertices per axis "
                f"({MAX_RESOLUTION}³ float32 samples already take {MAX_RESOLUTION**3 * 4 / 2**30:.0f} GiB)",
                "use e.g. --resolution 256 (384-512 for fine detail)",
            )
    return int(values[0]), int(values[1]), int(values[2])


def check_bbox(bbox_min: Sequence[float], bbox_max: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Finite 3-vectors with min < max on every axis."""
    lo = np.asarray(bbox_min, dtype=np.float64).reshape(-1)
    hi = np.asarray(bbox_max, dtype=np.float64).reshape(-1)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        fail(
            f"--bbox-min {list(lo)} / --bbox-max {list(hi)} must be three finite numbers each",
            "e.g. --bbox-min -1 -1 -1 --bbox-max 1 1 1",
        )
    bad = [axis for axis, a, b in zip("xyz", lo, hi, strict=True) if not a < b]
    if bad:
        fail(
            f"the export box has min >= max on axis {', '.join(bad)} "
            f"(--bbox-min {lo.tolist()}, --bbox-max {hi.tolist()})",
            "give --bbox-min strictly smaller than --bbox-max on every axis",
        )
    return lo, hi


def check_frequency_cap(frequency_cap: float | None) -> float | None:
    if frequency_cap is None:
        return None
    f = float(frequency_cap)
    if not 0.0 <= f <= 1.0:  # also false for NaN
        fail(
            f"--frequency-cap {frequency_cap} is outside [0, 1]",
            "give the kept share of the spectrum: 0 keeps only the mean (DC), 1 keeps every frequency",
        )
    return f


def check_level(level: Level, level_kind: LevelKind) -> None:
    if level == "auto":
        return
    if isinstance(level, str) or not math.isfinite(float(level)):
        fail(f"--level {level!r} must be 'auto' or a finite number", "e.g. --level auto or --level 0.5")
    if level_kind == "opacity" and not 0.0 < float(level) < 1.0:
        fail(
            f"--level {level} is not an opacity: with --level-kind opacity it must lie strictly between 0 and 1",
            "pass e.g. --level 0.5, or --level-kind density to give a density value",
        )


# -------------------------------------------------------------------------------------------------------- sampling
def sample_grid(
    fn: Callable[[Tensor], Tensor],
    bbox_min: Sequence[float],
    bbox_max: Sequence[float],
    resolution: int | Sequence[int],
    chunk: int = DEFAULT_CHUNK,
    device: torch.device | str | None = None,
) -> np.ndarray:
    """``fn`` (world points [N, 3] float32 -> values [N]) on the vertex grid spanning the box: float32 [Rx, Ry, Rz].

    The corners of the box are grid vertices (as in ``occupancy.vertex_grid``). Coordinates are built per chunk of
    ``chunk`` consecutive vertices (x-major order), so only the result volume is ever held at full size: a 512³
    export never materialises 512³ × 3 coordinates. The per-vertex coordinates do not depend on the chunking.
    """
    lo, hi = check_bbox(bbox_min, bbox_max)
    reso = check_resolution(resolution)
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")
    dev = torch.device(device) if device is not None else torch.device("cpu")
    axes = [torch.linspace(float(lo[i]), float(hi[i]), reso[i], device=dev, dtype=torch.float32) for i in range(3)]
    _, ry, rz = reso
    total = reso[0] * ry * rz
    out = torch.empty(total, dtype=torch.float32)
    with torch.no_grad():
        for start in range(0, total, chunk):
            idx = torch.arange(start, min(start + chunk, total), device=dev)
            xyz = torch.stack([axes[0][idx // (ry * rz)], axes[1][(idx // rz) % ry], axes[2][idx % rz]], dim=-1)
            values = fn(xyz)
            if values.shape != (idx.shape[0],):
                raise ValueError(f"fn must map [N, 3] points to [N] values, got shape {tuple(values.shape)}")
            out[start : start + idx.shape[0]] = values.detach().float().cpu()
    return out.view(*reso).numpy()


def auto_levels(level_kind: LevelKind, step_size: float, distance_scale: float) -> list[float]:
    """``AUTO_OPACITIES`` in the units of ``level_kind``."""
    if level_kind == "opacity":
        return list(AUTO_OPACITIES)
    return [-math.log1p(-alpha) / (step_size * distance_scale) for alpha in AUTO_OPACITIES]


def largest_piece_share(volume: np.ndarray, level: float) -> float:
    """The share of the grid points above ``level`` that the largest 26-connected piece of them holds (0: none)."""
    labels, count = ndimage.label(volume > level, structure=np.ones((3, 3, 3), dtype=bool))
    if count == 0:
        return 0.0
    sizes = np.bincount(labels.ravel())[1:]
    return float(sizes.max() / sizes.sum())


def solid_level(volume: np.ndarray, candidates: Sequence[float]) -> tuple[float, str]:
    """The highest candidate level at which the object is one solid piece (``SOLID_SHARE``), else the one where the
    largest piece holds the most; and a sentence that says which and why."""
    vmin, vmax = float(volume.min()), float(volume.max())
    tried = [(largest_piece_share(volume, level), level) for level in candidates if vmin < level < vmax]
    if not tried:
        fail(
            f"no automatic level fits: the sampled field ranges over [{vmin:.4g}, {vmax:.4g}]",
            "pass an explicit --level between those values, or export a later checkpoint",
        )
    for share, level in tried:
        if share >= SOLID_SHARE:
            return level, f"auto: the highest tried level whose largest piece holds {share:.0%} of the solid"
    share, level = max(tried)
    return level, f"auto: no tried level makes one solid piece; the largest holds {share:.0%} at this one"


def check_finite(volume: np.ndarray, level_kind: str, where: str = "") -> None:
    finite = np.isfinite(volume)
    if not finite.all():
        fail(
            f"the sampled {level_kind} has {int((~finite).sum())} non-finite values (NaN/inf){where}",
            "the checkpoint has diverged: export an earlier one with --checkpoint",
        )


def check_level_in_range(volume: np.ndarray, level: float, level_kind: str, where: str = "") -> tuple[float, float]:
    """The field's (min, max); an error when ``level`` is not strictly inside (no surface crosses it)."""
    check_finite(volume, level_kind, where)
    vmin, vmax = float(volume.min()), float(volume.max())
    if not vmin < level < vmax:
        hint = f"e.g. --level {0.5 * (vmin + vmax):.4g}" if vmin < vmax else "the field is constant here"
        sparse = " (the field is nearly empty: an early or under-trained checkpoint?)" if level >= vmax else ""
        fail(
            f"empty iso-surface: the sampled {level_kind} ranges over [{vmin:.4g}, {vmax:.4g}]{where}, "
            f"so the level {level:.4g} is never crossed{sparse}",
            f"pass a --level strictly between those values ({hint}; a lower level keeps more of the surface), "
            "or enlarge the box with --bbox-min/--bbox-max",
        )
    return vmin, vmax


# ---------------------------------------------------------------------------------------------------------- meshing
def extract_mesh(
    volume: np.ndarray, level: float, bbox_min: Sequence[float], bbox_max: Sequence[float]
) -> trimesh.Trimesh:
    """Iso-surface of ``volume`` (sampled by ``sample_grid`` over the box) at ``level``, in the box's coordinates.

    Vertex = bbox_min + index · spacing with spacing = (max − min)/(R − 1). Faces wind counter-clockwise seen from
    the low-valued side, so face normals point out of the dense region (skimage's ``gradient_direction="ascent"``
    gives that winding for fields that are high inside; its vertex normals point outwards either way).
    """
    lo, hi = check_bbox(bbox_min, bbox_max)
    volume = np.asarray(volume, dtype=np.float32)
    if volume.ndim != 3 or min(volume.shape) < MIN_RESOLUTION:
        raise ValueError(f"volume must be 3-D with >= 2 samples per axis, got shape {volume.shape}")
    check_level_in_range(volume, float(level), "field")
    spacing = tuple(float(s) for s in (hi - lo) / (np.asarray(volume.shape) - 1))
    verts, faces, normals, _ = marching_cubes(volume, float(level), spacing=spacing, gradient_direction="ascent")
    verts = verts.astype(np.float64) + lo
    return trimesh.Trimesh(vertices=verts, faces=faces, vertex_normals=normals, process=False)


def component_labels(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per-face label of its connected piece (faces sharing an edge are connected)."""
    if len(mesh.faces) == 0:
        return np.zeros(0, dtype=np.int64)
    return trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))


def remove_small_components(
    mesh: trimesh.Trimesh, min_faces: int | None = 0, keep_largest: int | None = None
) -> tuple[trimesh.Trimesh, int, int]:
    """Drop pieces with fewer than ``min_faces`` faces (None: ``SMALL_PIECE`` of the largest piece's) and all but the
    ``keep_largest`` biggest.

    Returns (mesh, pieces kept, pieces removed). Floaters of a few-shot field are exactly such small pieces.
    """
    if min_faces is None:
        labels = component_labels(mesh)
        min_faces = math.ceil(SMALL_PIECE * int(np.bincount(labels).max())) if labels.size else 0
    if min_faces < 0:
        fail(f"--min-component-faces {min_faces} is negative", "pass 0 to keep every piece, or a face count")
    if keep_largest is not None and keep_largest < 1:
        fail(f"--keep-largest {keep_largest} must be at least 1", "omit it to keep every piece")
    labels = component_labels(mesh)
    sizes = np.bincount(labels) if labels.size else np.zeros(0, dtype=np.int64)
    keep = sizes >= min_faces
    if keep_largest is not None:
        order = np.argsort(-sizes, kind="stable")
        keep[order[keep_largest:]] = False
    kept, removed = int(keep.sum()), int((~keep).sum())
    if removed == 0:
        return mesh, kept, 0
    if kept == 0:
        fail(
            f"every one of the {len(sizes)} mesh pieces has fewer than --min-component-faces {min_faces} faces "
            f"(the largest has {int(sizes.max())})",
            f"lower --min-component-faces to at most {int(sizes.max())}",
        )
    out = mesh.copy()
    out.update_faces(keep[labels])
    out.remove_unreferenced_vertices()
    return out, kept, removed


def vertex_colors(
    rgb_fn: Callable[[Tensor, Tensor | None], Tensor],
    vertices: np.ndarray,
    normals: np.ndarray,
    view_dependent: bool,
    chunk: int = DEFAULT_CHUNK,
    device: torch.device | str | None = None,
) -> np.ndarray:
    """uint8 RGBA [V, 4] from the appearance field; a view-dependent field is seen head-on (direction −normal)."""
    dev = torch.device(device) if device is not None else torch.device("cpu")
    out = np.empty((len(vertices), 4), dtype=np.uint8)
    out[:, 3] = 255
    with torch.no_grad():
        for start in range(0, len(vertices), chunk):
            # torch.tensor copies: trimesh hands out read-only arrays.
            pts = torch.tensor(np.asarray(vertices[start : start + chunk]), dtype=torch.float32, device=dev)
            dirs = None
            if view_dependent:
                n = torch.tensor(np.asarray(normals[start : start + chunk]), dtype=torch.float32, device=dev)
                dirs = -torch.nn.functional.normalize(n, dim=-1)
            rgb = rgb_fn(pts, dirs).clamp(0.0, 1.0).cpu().numpy()
            out[start : start + len(pts), :3] = (rgb * 255.0 + 0.5).astype(np.uint8)
    return out


def write_mesh(mesh: trimesh.Trimesh, path: Path) -> None:
    """Write in the format of ``path``'s suffix, creating the parent folder; a temporary sibling is renamed into
    place, so an interrupted write never leaves a truncated mesh under the name."""
    file_type = check_suffix(path)
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        mesh.export(str(tmp), file_type=file_type)
        os.replace(tmp, path)
    except OSError as err:
        problem = user_error_for(err, path=path)
        if problem is not None:
            raise problem from err
        raise UserError(f"cannot write the mesh to {path}: {err}", "choose a writable --output-path") from err
    finally:
        tmp.unlink(missing_ok=True)


# ---------------------------------------------------------------------------------------------------- trained model
def export_field_mesh(
    model: Any,
    step: int,
    output_path: Path | None,
    resolution: int | Sequence[int] = 256,
    bbox: tuple[Sequence[float], Sequence[float]] | None = None,
    level: Level = "auto",
    level_kind: LevelKind = "opacity",
    colors: bool = False,
    frequency_cap: float | None = None,
    min_component_faces: int | None = None,
    keep_largest: int | None = None,
    chunk: int = DEFAULT_CHUNK,
    frame: MeshFrame | None = None,
) -> MeshReport:
    """Marching cubes of a FourieRF/TensoRF model's density, written to ``output_path`` (None: not written).

    ``step`` picks the Fourier cutoffs (``model.cutoffs(step)``); ``frequency_cap`` f instead filters both density
    and colour grids at f, i.e. the coarse geometry the field holds below that share of the spectrum. ``bbox``
    (field coordinates) defaults to the model's current AABB. ``frame`` says where the vertices are written (default:
    the field's own coordinates). The model is left as it was (``field.filtered_at`` restores its filtering).
    """
    started = time.perf_counter()
    if output_path is not None:
        check_suffix(output_path)
    reso = check_resolution(resolution)
    cap = check_frequency_cap(frequency_cap)
    check_level(level, level_kind)
    if min_component_faces is not None and min_component_faces < 0:
        fail(f"--min-component-faces {min_component_faces} is negative", "pass 0 to keep every piece")
    if keep_largest is not None and keep_largest < 1:
        fail(f"--keep-largest {keep_largest} must be at least 1", "omit it to keep every piece")
    free = available_memory()
    if free is not None:
        largest = int((free / BYTES_PER_VERTEX) ** (1 / 3) + 1e-6)
        check_fits(
            BYTES_PER_VERTEX * math.prod(reso),
            f"a {reso[0]}x{reso[1]}x{reso[2]} marching-cubes grid (--resolution)",
            f"pass at most --resolution {largest} on this machine",
            free,
        )
    aabb = model.aabb.detach().cpu().double().numpy()
    lo, hi = check_bbox(*(bbox if bbox is not None else (aabb[0], aabb[1])))
    device = model.aabb.device
    step_size, distance_scale = float(model.step_size), float(model.config.distance_scale)

    cutoffs = model.cutoffs(step) if cap is None else (cap, cap)
    with model.field.filtered_at(*cutoffs):

        def field_values(xyz: Tensor) -> Tensor:
            sigma = model.field.density(xyz)
            return sigma if level_kind == "density" else opacity_from_density(sigma, step_size, distance_scale)

        volume = sample_grid(field_values, lo, hi, reso, chunk=chunk, device=device)
        sample_seconds = time.perf_counter() - started
        where = f" at resolution {reso[0]}x{reso[1]}x{reso[2]} in the box {lo.tolist()} - {hi.tolist()}"
        if level == "auto":
            check_finite(volume, level_kind, where)
            value, level_reason = solid_level(volume, auto_levels(level_kind, step_size, distance_scale))
        else:
            value, level_reason = float(level), "as given"
        field_range = check_level_in_range(volume, value, level_kind, where)
        mesh = extract_mesh(volume, value, lo, hi)
        mesh, components, removed = remove_small_components(mesh, min_component_faces, keep_largest)
        if colors:
            mesh.visual.vertex_colors = vertex_colors(
                model.field.rgb, mesh.vertices, mesh.vertex_normals, model.effects.view_dependent, chunk, device
            )
    frame = frame if frame is not None else field_frame(model.effects.ray_space)
    mesh, dropped = map_mesh(mesh, frame)
    if len(mesh.faces) == 0:
        fail(
            f"every face of the mesh lies beyond the scene's far bound once mapped to the {frame.space} frame",
            "export with --frame field, or narrow the box with --bbox-min/--bbox-max",
        )
    if output_path is not None:
        write_mesh(mesh, output_path)
    bounds = mesh.bounds
    return MeshReport(
        path=None if output_path is None else Path(output_path),
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        bounds=(tuple(bounds[0].tolist()), tuple(bounds[1].tolist())),
        watertight=bool(mesh.is_watertight),
        components=components,
        removed_components=removed,
        level=value,
        level_reason=level_reason,
        level_kind=level_kind,
        field_range=field_range,
        resolution=reso,
        bbox=(tuple(lo.tolist()), tuple(hi.tolist())),
        space=frame.space,
        frame_note=frame.note,
        dropped_far_faces=dropped,
        step=int(step),
        frequency_cap=cap,
        seconds=time.perf_counter() - started,
        sample_seconds=sample_seconds,
    )


def describe(report: MeshReport) -> list[str]:
    """Human summary lines (plain text; the CLI and the trainer print them)."""

    def vec(v: Sequence[float]) -> str:
        return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"

    r = report
    cutoff = f"frequency cap {r.frequency_cap:g}" if r.frequency_cap is not None else f"cutoffs of step {r.step}"
    lines = [
        f"{r.vertices} vertices, {r.faces} faces, {r.components} component(s)"
        + (f" ({r.removed_components} small ones removed)" if r.removed_components else "")
        + f", watertight: {'yes' if r.watertight else 'no'}",
        f"bounds {vec(r.bounds[0])} - {vec(r.bounds[1])} ({r.space} frame)",
        f"level {r.level_kind} {r.level:.4g} ({r.level_reason}; field range {r.field_range[0]:.4g} .. "
        f"{r.field_range[1]:.4g}), "
        f"grid {r.resolution[0]}x{r.resolution[1]}x{r.resolution[2]}, {cutoff}",
        f"took {r.seconds:.2f}s (sampling {r.sample_seconds:.2f}s)",
    ]
    lines.append(r.frame_note)
    if r.dropped_far_faces:
        lines.append(f"{r.dropped_far_faces} faces reaching beyond the scene's far bound left out")
    if r.path is not None:
        lines.append(f"wrote {r.path}")
    return lines
