"""``AcceleratedOps`` computes what the reference ``GridOps`` computes, on the same field parameters.

The field is built twice with identical parameters, once with each implementation. Density and colour agree to
rounding in training (with equal gradients for every parameter) and in renders, for VM and CP, with and without
view dependence, whether the dense vertex tables are built or not. The budgets (``dense_train_max_vertices``,
``dense_render_max_mb``) decide which tables are built, and when (at the first lookup of their kind, once per
filtering, reused by every view of a render until a parameter or cutoff changes); row-major factor copies are made
in renders only; bfloat16 is used where ``decoder_precision`` and the device say so, never for float64, and stays
within bf16 precision of float32; colour of large training batches in checkpointed chunks changes nothing.
``build_ops`` gives the reference for backend "reference-grid-ops".
"""

from __future__ import annotations

from typing import Any

import pytest
import torch
import torch.nn.functional as F

from fourierf_plugin.accel import AccelConfig, AcceleratedOps, build_ops
from fourierf_plugin.accel.lookups import GATHER, RowTable
from fourierf_plugin.accel.ops import native_bfloat16
from fourierf_plugin.field_components.tensor_grids import GRID_SAMPLE
from fourierf_plugin.fields.fourier_tensorf_field import FourierTensoRFField
from fourierf_plugin.fields.grid_ops import GridOps
from tests.fields.test_field import AABB, small_field
from tests.helpers import rays_through_the_slab, slab_model

APPEARANCE_DIM = 6  # small_field's; RESO has 315 vertices
CUTOFFS = (0.4, 0.7)
NO_TABLES = {"dense_train_max_vertices": 0, "dense_render_max_mb": 0}
ALL_TABLES = {"dense_train_max_vertices": 10**6, "dense_render_max_mb": 1.0}


def _accelerated(**config: object) -> AcceleratedOps:
    """Accelerated ops on CPU, float32 decoder unless said otherwise (auto would pick bf16 on some CPUs)."""
    return AcceleratedOps(AccelConfig(**{"decoder_precision": "float32", **config}), "cpu")  # type: ignore[arg-type]


def _field(
    ops: GridOps | None = None,
    decomposition: str = "vm",
    view_dependent: bool = False,
    dtype: torch.dtype = torch.float32,
    **options: Any,
) -> FourierTensoRFField:
    """The small field of the reference tests with leaky planes; the same parameters whatever ``ops`` it is given.
    ``options`` are the field's own (``mirror_boundary``, ``density_axes``)."""
    field_kw = {"ops": ops, "plane_leakage": 1e-6, **options}
    return small_field(decomposition, view_dependent, field_kw, dtype, init_scale=0.5)


def _points(n: int, dtype: torch.dtype = torch.float32, seed: int = 3) -> torch.Tensor:
    u = torch.rand(n, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64) * 1.1 - 0.05
    return (AABB[0] + u * (AABB[1] - AABB[0])).to(dtype)  # a few points just outside the box


def _directions(n: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    return F.normalize(torch.randn(n, 3, generator=torch.Generator().manual_seed(5), dtype=dtype), dim=-1)


def _outputs(
    field: FourierTensoRFField, xyz: torch.Tensor, directions: torch.Tensor | None, training: bool
) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
    """Density, colour and (in training) every parameter's gradient of a fixed weighting of both."""
    with torch.set_grad_enabled(training):
        field.prepare(*CUTOFFS)
        density, rgb = field.density(xyz), field.rgb(xyz, directions)
    grads = {}
    if training:
        weights = torch.linspace(0.5, 1.5, rgb.numel(), dtype=rgb.dtype).view_as(rgb)
        (density.sum() + (rgb * weights).sum()).backward()
        grads = {name: p.grad for name, p in field.named_parameters()}
    return density.detach(), rgb.detach(), grads


def _tables(field: FourierTensoRFField) -> set[str]:
    """The kinds whose dense table this filtering built (a None in the cache: decided not to fit)."""
    g = field.filtered
    kinds = (("density", g.density), ("appearance", g.appearance))
    return {kind for kind, factors in kinds if factors.cache.get(f"dense_{kind}") is not None}


# ------------------------------------------------------------------------------------------- parity with GridOps
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("budgets", [ALL_TABLES, NO_TABLES], ids=["tables", "factors"])
@pytest.mark.parametrize("training", [True, False], ids=["training", "render"])
@pytest.mark.parametrize("view_dependent", [False, True])
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_accelerated_ops_equal_the_reference(
    decomposition: str, view_dependent: bool, training: bool, budgets: dict, dtype: torch.dtype
) -> None:
    xyz = _points(300, dtype)
    directions = _directions(300, dtype) if view_dependent else None
    reference = _outputs(_field(GridOps(), decomposition, view_dependent, dtype), xyz, directions, training)
    accelerated = _field(_accelerated(**budgets), decomposition, view_dependent, dtype)
    ours = _outputs(accelerated, xyz, directions, training)
    tables = {"density"} if training else {"density", "appearance"}
    assert _tables(accelerated) == (tables if budgets is ALL_TABLES else set())
    tol = {"atol": 1e-5, "rtol": 1e-5} if dtype == torch.float32 else {"atol": 1e-11, "rtol": 1e-11}
    assert ours[1].dtype == dtype
    torch.testing.assert_close(ours[0], reference[0], **tol)
    torch.testing.assert_close(ours[1], reference[1], **tol)
    assert ours[2].keys() == reference[2].keys()
    for name, grad in reference[2].items():
        assert grad is not None and torch.isfinite(ours[2][name]).all(), name
        torch.testing.assert_close(ours[2][name], grad, **tol, msg=name)


@pytest.mark.parametrize("decomposition", ["vm", "cp"])
@pytest.mark.parametrize(
    "options", [{"mirror_boundary": True}, {"density_axes": (0, 1)}, {"mirror_boundary": True, "density_axes": (0, 1)}]
)
def test_accelerated_ops_equal_the_reference_with_field_options(decomposition: str, options: dict) -> None:
    # The fast filters see the mirror-extended factors, or planes filtered along one axis (transposed where that axis
    # is the height); their backward is the same filter, still exact.
    xyz = _points(300, torch.float64)
    reference = _outputs(_field(GridOps(), decomposition, dtype=torch.float64, **options), xyz, None, True)
    plain = _outputs(_field(GridOps(), decomposition, dtype=torch.float64), xyz, None, True)
    ours = _outputs(_field(_accelerated(), decomposition, dtype=torch.float64, **options), xyz, None, True)
    assert not torch.allclose(reference[0], plain[0])
    torch.testing.assert_close(ours[0], reference[0], atol=1e-11, rtol=1e-11)
    torch.testing.assert_close(ours[1], reference[1], atol=1e-11, rtol=1e-11)
    for name, grad in reference[2].items():
        torch.testing.assert_close(ours[2][name], grad, atol=1e-11, rtol=1e-11, msg=name)


# -------------------------------------------------------------------------------------------------- dense tables
@pytest.mark.parametrize(
    ("budgets", "train_kinds", "render_kinds"),
    [
        (ALL_TABLES, {"density"}, {"density", "appearance"}),
        # 315 vertices: the density fits in training at 315 and in renders at 315 floats; 6 appearance channels do not
        ({"dense_train_max_vertices": 315, "dense_render_max_mb": 315 * 4 / 2**20}, {"density"}, {"density"}),
        ({"dense_train_max_vertices": 314, "dense_render_max_mb": 315 * 4 / 2**20 - 1e-9}, set(), set()),
        ({"dense_train_max_vertices": 10, "dense_render_max_mb": 315 * 4 * APPEARANCE_DIM / 2**20}, set(),
         {"density", "appearance"}),
    ],
)  # fmt: skip
def test_dense_table_budgets_decide_what_is_built_and_values_stay_the_same(
    budgets: dict, train_kinds: set[str], render_kinds: set[str]
) -> None:
    """Training bakes only the density (differentiably) up to a vertex count; renders bake each table within a MB
    budget; every combination gives the reference's density and colour."""
    xyz = _points(200)
    reference = [_outputs(_field(GridOps()), xyz, None, training) for training in (True, False)]
    field = _field(_accelerated(**budgets))
    for training, kinds, ref in zip((True, False), (train_kinds, render_kinds), reference, strict=True):
        density, rgb, _ = _outputs(field, xyz, None, training)
        assert _tables(field) == kinds, "training" if training else "render"
        torch.testing.assert_close(density, ref[0], atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(rgb, ref[1], atol=1e-6, rtol=1e-5)


def test_dense_density_in_training_gives_finite_gradients_to_every_factor() -> None:
    field = _field(_accelerated(**ALL_TABLES))
    field.prepare(0.4, 0.4)
    field.density(_points(64)).sum().backward()
    assert _tables(field) == {"density"}
    for p in field.density_grid.parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all()
        assert float(p.grad.abs().sum()) > 0


def test_renders_reuse_the_tables_until_a_parameter_or_cutoff_changes() -> None:
    field = _field(_accelerated(**ALL_TABLES))
    xyz = _points(16)

    def render(f_density: float) -> tuple[object, object]:
        field.prepare(f_density, 0.5)
        field.density(xyz), field.rgb(xyz, None)
        return field.filtered.density.cache["dense_density"], field.filtered.appearance.cache["dense_appearance"]

    with torch.no_grad():
        first = render(0.5)
        assert all(isinstance(t, torch.Tensor) for t in first)
        again = render(0.5)
        assert all(a is b for a, b in zip(again, first, strict=True))  # the next view: nothing rebuilt
        second = render(0.6)
        assert all(a is not b for a, b in zip(second, first, strict=True))
        field.appearance_grid.lines[0].add_(0.1)  # an optimiser step changes parameters in place
        third = render(0.6)
        assert all(a is not b for a, b in zip(third, second, strict=True))
        field.invalidate()
        assert all(a is not b for a, b in zip(render(0.6), third, strict=True))


def test_tables_are_built_at_the_first_lookup_of_their_kind_only() -> None:
    """A prepare that only reads the factors (an upsample) or only the density (an occupancy update) bakes no
    appearance table: the biggest one."""
    field = _field(_accelerated(**ALL_TABLES))
    with torch.no_grad():
        field.prepare(0.5, 0.5)
        assert field.filtered.density.cache == {} and field.filtered.appearance.cache == {}
        field.density(_points(8))
        assert _tables(field) == {"density"} and field.filtered.appearance.cache == {}
        field.rgb(_points(8), None)
        assert _tables(field) == {"density", "appearance"}


@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_row_tables_are_made_in_renders_only(decomposition: str) -> None:
    """Renders read row-major copies of the factors (transposed once per filtering), training the factors."""
    field = _field(_accelerated(**NO_TABLES), decomposition)
    xyz = _points(50)
    field.prepare(0.5, 0.5)
    trained = field.density(xyz).detach()
    assert "rows" not in field.filtered.density.cache
    with torch.no_grad():
        field.prepare(0.5, 0.5)
        assert field.filtered.density.cache == {}  # made at the first lookup, not before
        rendered = field.density(xyz)
        planes, lines = field.filtered.density.cache["rows"]
        assert "rows" not in field.filtered.appearance.cache
    assert all(isinstance(t, RowTable) for t in (*planes, *lines)) and len(lines) == 3
    torch.testing.assert_close(rendered, trained)


def test_the_device_picks_the_lookup() -> None:
    """Gathers on CPU (grid_sample's CPU kernels are the slow part there), the reference grid_sample elsewhere."""
    cpu, cuda = _accelerated(), AcceleratedOps(AccelConfig(), torch.device("cuda"))
    assert cpu.gather and cpu.lookup is GATHER
    assert not cuda.gather and cuda.lookup is GRID_SAMPLE


# ------------------------------------------------------------------------------------------------- precision
@pytest.mark.parametrize(
    ("precision", "device", "renders", "training"),
    [
        ("float32", "cpu", False, False),
        ("bfloat16", "cpu", True, True),
        ("auto", "cpu", None, False),  # None: renders in bf16 exactly where the CPU has native bf16
        ("auto", "cuda", False, False),
        ("bfloat16", "cuda", False, False),  # the autocast is CPU's; other devices keep float32
    ],
)
def test_bf16_is_decided_by_the_precision_and_the_device(
    precision: str, device: str, renders: bool | None, training: bool
) -> None:
    ops = AcceleratedOps(AccelConfig(decoder_precision=precision), device)  # type: ignore[arg-type]
    expected_renders = native_bfloat16(torch.device("cpu")) if renders is None else renders
    assert ops.bf16_renders == expected_renders and ops.bf16_training == training
    assert native_bfloat16(torch.device("cpu")) == bool(torch.cpu._is_avx512_bf16_supported())
    assert not native_bfloat16(torch.device("cuda"))


def test_float64_models_are_never_downcast() -> None:
    xyz, directions = _points(100, torch.float64), _directions(100, torch.float64)
    for training in (True, False):
        ref = _outputs(_field(GridOps(), view_dependent=True, dtype=torch.float64), xyz, directions, training)
        forced = _field(_accelerated(decoder_precision="bfloat16"), view_dependent=True, dtype=torch.float64)
        ours = _outputs(forced, xyz, directions, training)
        assert ours[1].dtype == torch.float64
        torch.testing.assert_close(ours[1], ref[1], atol=1e-11, rtol=1e-11)


@pytest.mark.parametrize("training", [True, False], ids=["training", "render"])
def test_bfloat16_decoder_matches_float32_to_its_precision_with_finite_gradients(training: bool) -> None:
    xyz, directions = _points(500), _directions(500)
    ref = _outputs(_field(_accelerated(), view_dependent=True), xyz, directions, training)
    low = _outputs(_field(_accelerated(decoder_precision="bfloat16"), view_dependent=True), xyz, directions, training)
    assert low[1].dtype == torch.float32
    err = (low[1] - ref[1]).abs().max().item()
    assert 0 < err < 1e-2, err  # it did run in bf16 (not bit-equal) and stays within a few bf16 ulps of a colour
    torch.testing.assert_close(low[0], ref[0])  # the density never goes through the decoder
    if training:
        assert low[2].keys() == ref[2].keys()
        assert all(g is not None and bool(torch.isfinite(g).all()) for g in low[2].values())


# ----------------------------------------------------------------------------------- checkpointed training colour
def _train_forward(checkpoint_above: int) -> tuple[torch.Tensor, dict[str, torch.Tensor], list[int]]:
    """A training forward of the slab model; the sizes of the colour computations, recomputations included."""
    model = slab_model(0.05, accel=AccelConfig(checkpoint_above=checkpoint_above, checkpoint_chunk=50))
    assert isinstance(model.field.ops, AcceleratedOps)
    grid = model.field.appearance_grid
    calls: list[int] = []
    features = grid.features

    def counted(planes, lines, xyz, lookup):  # every colour computation reads the appearance grid once
        calls.append(xyz.shape[0])
        return features(planes, lines, xyz, lookup)

    grid.features = counted  # type: ignore[method-assign]
    model.train()
    model.prepare(5)
    origins, directions = rays_through_the_slab(32)
    out = model(origins, directions)
    out["rgb"].square().sum().backward()
    grads = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    return out["rgb"].detach(), grads, calls


def test_checkpointed_chunks_give_the_same_colours_and_gradients() -> None:
    rgb, grads, calls = _train_forward(checkpoint_above=0)
    assert len(calls) == 1
    shaded = calls[0]
    assert shaded > 120  # enough samples to be split below
    chunked_rgb, chunked_grads, chunked_calls = _train_forward(checkpoint_above=100)
    # Each 50-sample chunk runs twice: once forward, once recomputed in the backward pass.
    chunks = [50] * (shaded // 50) + ([shaded % 50] if shaded % 50 else [])
    assert chunked_calls[: len(chunks)] == chunks
    assert sorted(chunked_calls) == sorted(chunks * 2)
    torch.testing.assert_close(chunked_rgb, rgb, atol=0, rtol=0)
    assert grads.keys() == chunked_grads.keys() and any(k.startswith("field.decoder") for k in grads)
    for name, grad in grads.items():
        torch.testing.assert_close(chunked_grads[name], grad, atol=1e-7, rtol=1e-5, msg=name)


def test_few_shaded_samples_are_not_checkpointed() -> None:
    _, _, calls = _train_forward(checkpoint_above=10**6)
    assert len(calls) == 1  # one forward, nothing recomputed


# --------------------------------------------------------------------------------------------------- build_ops
def test_build_ops_picks_the_backend() -> None:
    assert type(build_ops(AccelConfig(backend="reference-grid-ops"), "cpu")) is GridOps
    accelerated = build_ops(AccelConfig(), "cpu")
    assert isinstance(accelerated, AcceleratedOps) and accelerated.name == "accelerated"
    reference_model = slab_model(0.05, accel=AccelConfig(backend="reference-grid-ops"))
    assert type(reference_model.field.ops) is GridOps
    assert isinstance(slab_model(0.05).field.ops, AcceleratedOps)


def test_reference_and_accelerated_models_render_the_same_colours() -> None:
    """The whole model's forward (sampling, marching, compositing) on each backend, training and rendering."""
    models = [
        slab_model(0.05, accel=AccelConfig(backend=b, decoder_precision="float32"))
        for b in ("reference", "accelerated")
    ]
    reference, accelerated = models
    accelerated.load_state_dict(reference.state_dict())
    origins, directions = rays_through_the_slab(16)
    for model in models:
        model.train()
        model.prepare(5)
    out = [m(origins, directions)["rgb"] for m in models]
    torch.testing.assert_close(out[1], out[0], atol=1e-5, rtol=1e-5)
    renders = [m.render_rays(origins, directions, step=5)["rgb"] for m in models]
    torch.testing.assert_close(renders[1], renders[0], atol=1e-5, rtol=1e-5)
