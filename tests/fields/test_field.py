"""The FourieRF field with the reference ``GridOps``: filtering, coordinate normalisation, density and colour
(spec 3.1, 4.4, 7.2, 7.10).

``prepare`` filters once and every lookup reads that; ``filtered_at`` evaluates at other cutoffs without gradients
and restores what was prepared; lookups before ``prepare`` (or after ``invalidate``) raise; density and colour follow
the spec's activations exactly. The accelerated operations are compared with these in ``tests/accel/test_ops.py``.
"""

from __future__ import annotations

from typing import Any

import pytest
import torch
import torch.nn.functional as F

from fourierf_plugin.field_components import fourier
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig, FourierTensoRFField
from fourierf_plugin.fields.grid_ops import GridOps

AABB = torch.tensor([[-1.5, -0.5, 0.0], [1.5, 2.5, 1.0]])
RESO = [5, 7, 9]


def small_field(
    decomposition: str = "vm",
    view_dependent: bool = False,
    field_kw: dict[str, Any] | None = None,
    dtype: torch.dtype = torch.float32,
    **kw: object,
) -> FourierTensoRFField:
    """A small field on ``AABB`` at ``RESO`` with 6 appearance channels, the same parameters for the same arguments
    (``tests/accel/test_ops.py`` builds it with each ``GridOps``). ``kw`` are FieldConfig options, ``field_kw`` the
    field's own (ops, plane_leakage, ...)."""
    comps = (4, 3, 2) if decomposition == "vm" else (5, 5, 5)
    cfg = FieldConfig(
        decomposition=decomposition,  # type: ignore[arg-type]
        density_components=comps,
        appearance_components=comps,
        appearance_dim=6,
        hidden_dim=8,
        **kw,  # type: ignore[arg-type]
    )
    torch.manual_seed(0)  # the decoder's layers draw from the global generator
    generator = torch.Generator().manual_seed(0)
    return FourierTensoRFField(cfg, AABB, list(RESO), view_dependent, generator, **(field_kw or {})).to(dtype)


def _points(n: int, seed: int = 3) -> torch.Tensor:
    u = torch.rand(n, 3, generator=torch.Generator().manual_seed(seed))
    return AABB[0] + u * (AABB[1] - AABB[0])


def _fill(field: FourierTensoRFField, plane_value: float, line_value: float) -> None:
    with torch.no_grad():
        for p in field.density_grid.planes:
            p.fill_(plane_value)
        for line in field.density_grid.lines:
            line.fill_(line_value)


# ------------------------------------------------------------------------------------------------------- cache
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_f1_filtered_grids_are_the_raw_parameters(decomposition: str) -> None:
    field = small_field(decomposition)
    assert type(field.ops) is GridOps  # the reference operations unless a model passes others
    g = field.filter(1.0, 1.0)
    assert g.cutoffs == (1.0, 1.0)
    assert all(a is b for a, b in zip(g.density.planes, field.density_grid.planes, strict=True))
    assert all(a is b for a, b in zip(g.density.lines, field.density_grid.lines, strict=True))
    assert all(a is b for a, b in zip(g.appearance.planes, field.appearance_grid.planes, strict=True))
    assert all(a is b for a, b in zip(g.appearance.lines, field.appearance_grid.lines, strict=True))
    assert len(g.density.lines) == 3
    assert len(g.density.planes) == (3 if decomposition == "vm" else 0)
    assert not g.density.rendering and not g.appearance.rendering


def test_filter_applies_the_cutoffs_and_the_plane_leakage() -> None:
    field = small_field(field_kw={"plane_leakage": 1e-3})
    g = field.filter(1.0, 0.0)
    for p, raw in zip(g.density.planes, field.density_grid.planes, strict=True):  # f = 1: the official 1 + leakage
        torch.testing.assert_close(p, raw * (1 + 1e-3))
    for line in g.appearance.lines:  # f = 0 on lines: the line mean only
        torch.testing.assert_close(line, line.mean(dim=-1, keepdim=True).expand_as(line), atol=1e-6, rtol=0)
    for p, raw in zip(g.appearance.planes, field.appearance_grid.planes, strict=True):  # f = 0: mean + leakage * P
        mean = raw.mean(dim=(-2, -1), keepdim=True)
        torch.testing.assert_close(p, mean + 1e-3 * raw, atol=1e-6, rtol=0)
    with torch.no_grad():
        assert field.filter(0.5, 0.5).density.rendering


def test_lookup_before_prepare_raises() -> None:
    field = small_field()
    xyz = _points(4)
    with pytest.raises(RuntimeError, match="prepare"):
        field.density(xyz)
    with pytest.raises(RuntimeError, match="prepare"):
        field.rgb(xyz, None)


def test_invalidate_then_lookup_raises() -> None:
    field = small_field()
    field.prepare(1.0, 1.0)
    field.density(_points(4))
    field.invalidate()
    with pytest.raises(RuntimeError):
        field.density(_points(4))
    with pytest.raises(RuntimeError):
        _ = field.filtered


def test_prepare_caches_one_filtering_per_call() -> None:
    field = small_field()
    field.prepare(0.3, 0.5)
    first = field.filtered
    assert field.filtered is first  # every lookup of the iteration reuses it
    field.prepare(0.3, 0.5)
    assert field.filtered is not first


def test_renders_reuse_the_filtering_until_a_parameter_or_cutoff_changes() -> None:
    field = small_field()
    with torch.no_grad():
        field.prepare(0.5, 0.5)
        first = field.filtered
        assert first.density.rendering and first.appearance.rendering
        field.prepare(0.5, 0.5)
        assert field.filtered is first  # the next view of the same render: nothing rebuilt
        field.prepare(0.6, 0.5)
        assert field.filtered is not first
        second = field.filtered
        field.density_grid.planes[0].add_(0.1)  # an optimiser step changes parameters in place
        field.prepare(0.6, 0.5)
        assert field.filtered is not second
        third = field.filtered
        field.invalidate()
        field.prepare(0.6, 0.5)
        assert field.filtered is not third
        fourth = field.filtered
    field.prepare(0.6, 0.5)  # training always filters afresh, with a graph
    assert field.filtered is not fourth and field.filtered.density.planes[0].requires_grad
    assert not field.filtered.density.rendering


def test_filtered_at_restores_the_previous_filtering() -> None:
    """An export between iterations evaluates at its own cutoffs, then the trainer's (autograd) filtering is back."""
    field = small_field(init_scale=1.0)
    xyz = _points(64)
    field.prepare(0.3, 0.4)
    prepared = field.filtered
    with field.filtered_at(1.0, 1.0) as inside:
        assert field.filtered is inside and inside is not prepared
        assert inside.cutoffs == (1.0, 1.0)
    assert field.filtered is prepared
    with pytest.raises(KeyError), field.filtered_at(0.0, 0.0):
        raise KeyError("an export failed")
    assert field.filtered is prepared  # restored on errors too
    (field.density(xyz).sum() + field.rgb(xyz, None).sum()).backward()  # the prepared graph still trains
    assert all(p.grad is not None for p in field.density_grid.parameters())


def test_filtered_at_works_without_gradients_and_lookups_see_its_cutoffs() -> None:
    """The block's filtering carries no graph (whether or not gradients are on around it), and every lookup in it
    reads the block's cutoffs."""
    field = small_field(init_scale=1.0)
    xyz = _points(64)
    with torch.no_grad():
        field.prepare(1.0, 1.0)
        full = field.density(xyz), field.rgb(xyz, None)
        field.prepare(0.0, 0.0)
        low = field.density(xyz), field.rgb(xyz, None)
    assert float((low[0] - full[0]).abs().max()) > 1e-6  # the cutoffs do change the field
    field.prepare(1.0, 1.0)  # training: with a graph
    with field.filtered_at(0.0, 0.0) as inside:
        assert torch.is_grad_enabled()  # the caller's mode is left alone; only the filtering is graph-free
        assert not any(t.requires_grad for g in (inside.density, inside.appearance) for t in (*g.planes, *g.lines))
        density = field.density(xyz)
        assert not density.requires_grad
        torch.testing.assert_close(density, low[0])
        torch.testing.assert_close(field.rgb(xyz, None).detach(), low[1])
    torch.testing.assert_close(field.density(xyz).detach(), full[0])  # the prepared f = 1 is back
    assert field.density(xyz).requires_grad
    with torch.no_grad(), field.filtered_at(0.0, 0.0):  # how exports call it
        torch.testing.assert_close(field.rgb(xyz, None), low[1])
    torch.testing.assert_close(field.rgb(xyz, None).detach(), full[1])


def test_filtered_at_without_a_previous_filtering_leaves_none() -> None:
    field = small_field()
    with field.filtered_at(0.5, 0.5):
        field.density(_points(4))
    with pytest.raises(RuntimeError, match="prepare"):
        field.density(_points(4))


def test_app_planes_follow_density_cutoff() -> None:
    field = small_field(field_kw={"app_planes_follow_density": True})
    g = field.filter(0.0, 1.0)
    for p in g.appearance.planes:  # f = 0 on planes: the plane mean only
        torch.testing.assert_close(p, p.mean(dim=(-2, -1), keepdim=True).expand_as(p), atol=1e-6, rtol=0)
    assert all(a is b for a, b in zip(g.appearance.lines, field.appearance_grid.lines, strict=True))
    plain = small_field()  # without the option the appearance planes take the colour cutoff
    g = plain.filter(0.0, 1.0)
    assert all(a is b for a, b in zip(g.appearance.planes, plain.appearance_grid.planes, strict=True))


def test_mirror_boundary_filters_each_factor_with_its_mirror_image() -> None:
    field = small_field(field_kw={"mirror_boundary": True})
    g = field.filter(0.4, 0.0)
    for p, raw in zip(g.density.planes, field.density_grid.planes, strict=True):
        torch.testing.assert_close(p, fourier.mirrored(fourier.filter_planes, raw, 0.4, 2, 0.0))
        assert not torch.allclose(p, fourier.filter_planes(raw, 0.4))  # not the periodic filter
    for line in g.appearance.lines:  # f = 0: the mean under either boundary
        torch.testing.assert_close(line, line.mean(dim=-1, keepdim=True).expand_as(line), atol=1e-6, rtol=0)
    g = field.filter(1.0, 1.0)  # the band open: the raw factors themselves, as without mirroring
    assert all(a is b for a, b in zip(g.density.lines, field.density_grid.lines, strict=True))


@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_density_axes_leave_the_other_axes_unfiltered(decomposition: str) -> None:
    """Density filtered along x and y only (a forward-facing scene's image plane): factors along z are the raw ones,
    planes across z are low-passed along their in-plane axis alone, and every appearance factor as before."""
    field = small_field(decomposition, field_kw={"density_axes": (0, 1)})
    plain = small_field(decomposition)
    g, reference = field.filter(0.0, 0.0), plain.filter(0.0, 0.0)
    grid = field.density_grid
    for line, raw, axis in zip(g.density.lines, grid.lines, grid.line_axes, strict=True):
        if axis == 2:
            assert line is raw
        else:  # f = 0: the line mean
            torch.testing.assert_close(line, raw.mean(dim=-1, keepdim=True).expand_as(raw), atol=1e-6, rtol=0)
    for p, raw, spans in zip(g.density.planes, grid.planes, grid.plane_axes, strict=True):
        if spans == (0, 1):  # both axes filtered: the disc, at f = 0 the plane mean
            torch.testing.assert_close(p, raw.mean(dim=(-2, -1), keepdim=True).expand_as(raw), atol=1e-6, rtol=0)
        else:  # (x or y, z): the mean along the in-plane axis (W), every z row on its own
            assert spans[1] == 2
            torch.testing.assert_close(p, raw.mean(dim=-1, keepdim=True).expand_as(raw), atol=1e-6, rtol=0)
    appearance = (*g.appearance.planes, *g.appearance.lines)
    for a, b in zip(appearance, (*reference.appearance.planes, *reference.appearance.lines), strict=True):
        torch.testing.assert_close(a, b)
    z_only = small_field(decomposition, field_kw={"density_axes": (2,)})
    g = z_only.filter(0.0, 0.0)
    for p, raw, spans in zip(g.density.planes, z_only.density_grid.planes, z_only.density_grid.plane_axes, strict=True):
        if spans == (0, 1):  # no z in the plane: unfiltered
            assert p is raw
        else:  # the mean along z (H), every column on its own
            torch.testing.assert_close(p, raw.mean(dim=-2, keepdim=True).expand_as(raw), atol=1e-6, rtol=0)
    opened = field.filter(1.0, 1.0)  # the band open: the raw factors, as with every axis
    assert all(a is b for a, b in zip(opened.density.planes, grid.planes, strict=True))


def test_density_axes_with_mirror_boundary_mirror_along_the_filtered_axis_only() -> None:
    field = small_field(field_kw={"density_axes": (0, 1), "mirror_boundary": True})
    g = field.filter(0.4, 1.0)
    xz_plane = field.density_grid.planes[1]  # W along x (filtered), H along z (not)
    torch.testing.assert_close(g.density.planes[1], fourier.mirrored(fourier.filter_lines, xz_plane, 0.4, 1))
    assert g.density.lines[0] is field.density_grid.lines[0]  # the z line


def test_filtered_grids_carry_gradients_to_raw_parameters() -> None:
    field = small_field()
    field.prepare(0.5, 0.5)
    xyz = _points(32)
    (field.density(xyz).sum() + field.rgb(xyz, None).sum()).backward()
    for name, p in field.named_parameters():
        assert p.grad is not None, name
        assert torch.isfinite(p.grad).all(), name
    assert any(float(p.grad.abs().sum()) > 0 for p in field.density_grid.parameters())


# --------------------------------------------------------------------------------------------------- geometry
def test_normalize_maps_box_corners_to_unit_cube() -> None:
    field = small_field()
    corners = torch.tensor([[AABB[i, 0], AABB[j, 1], AABB[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    x = field.normalize(corners)
    expected = torch.tensor([[i, j, k] for i in (-1.0, 1.0) for j in (-1.0, 1.0) for k in (-1.0, 1.0)])
    torch.testing.assert_close(x, expected, atol=1e-6, rtol=0)
    torch.testing.assert_close(field.normalize(AABB.mean(dim=0, keepdim=True)), torch.zeros(1, 3), atol=1e-6, rtol=0)


def test_resolution_and_aabb_buffer() -> None:
    field = small_field()
    assert field.resolution == RESO
    assert "aabb" in dict(field.named_buffers())
    assert torch.equal(field.aabb, AABB)


# ------------------------------------------------------------------------------------------------------ density
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_density_nonnegative_finite(decomposition: str) -> None:
    field = small_field(decomposition)
    field.prepare(1.0, 1.0)
    sigma = field.density(_points(200))
    assert sigma.shape == (200,)
    assert torch.isfinite(sigma).all() and (sigma >= 0).all()


@pytest.mark.parametrize("a", [0.0, 0.5, -0.7, 2.0])
def test_density_softplus_shift_exact_vm(a: float) -> None:
    """planes = 1, lines = a: the σ feature is Σ_i C_i · a, and σ = softplus(feature - 10) everywhere."""
    field = small_field("vm")
    _fill(field, 1.0, a)
    field.prepare(1.0, 1.0)
    feature = sum(field.config.density_components) * a
    expected = F.softplus(torch.tensor(feature - 10.0))
    sigma = field.density(_points(50))
    torch.testing.assert_close(sigma, expected.expand(50), atol=1e-7, rtol=1e-6)


def test_density_cp_feature_is_sum_of_products() -> None:
    field = small_field("cp")
    with torch.no_grad():
        for value, line in zip((2.0, 0.5, 3.0), field.density_grid.lines, strict=True):
            line.fill_(value)
    field.prepare(1.0, 1.0)
    expected = F.softplus(torch.tensor(5 * 2.0 * 0.5 * 3.0 - 10.0))
    torch.testing.assert_close(field.density(_points(20)), expected.expand(20), atol=1e-7, rtol=1e-6)


def test_density_relu_activation() -> None:
    field = small_field("vm", density_activation="relu")
    _fill(field, 1.0, 2.0)  # feature = 9 * 2 = 18 -> relu(18) = 18: ReLU takes no shift (TensoRF)
    field.prepare(1.0, 1.0)
    torch.testing.assert_close(field.density(_points(10)), torch.full((10,), 18.0))
    _fill(field, 1.0, -0.5)  # feature -4.5 -> relu(-4.5) = 0 (the "dead" LLFF case, spec 7.2)
    field.prepare(1.0, 1.0)
    assert (field.density(_points(10)) == 0).all()


def _dark_batch_grads(field, batches: int) -> list[torch.Tensor]:
    """Sum of the density lines' gradients of each of ``batches`` training batches on a field dead everywhere."""
    grads = []
    for _ in range(batches):
        field.zero_grad()
        field.prepare(1.0, 1.0)
        sigma = field.density(_points(10))
        assert (sigma == 0).all()
        (-sigma.sum()).backward()  # a loss that wants more density
        grads.append(torch.stack([line.grad.sum() for line in field.density_grid.lines]))
    return grads


def test_dead_relu_field_still_learns_unless_plain_relu_is_asked_for() -> None:
    """A field whose density has been zero everywhere since its start gets a gradient telling it to grow from its
    ``revive_patience``-th dark batch on; ``revive_dead_density=False`` is TensoRF's ReLU, which leaves it dead."""
    patience = 3
    for revive in (True, False):
        field = small_field("vm", density_activation="relu", revive_dead_density=revive, revive_patience=patience)
        _fill(field, 1.0, -0.5)
        grads = _dark_batch_grads(field, patience + 1)
        assert all((g == 0).all() for g in grads[: patience - 1])  # a few dark batches: TensoRF's ReLU
        for g in grads[patience - 1 :]:
            assert (g < 0).all() if revive else (g == 0).all()  # descent raises the lines' values, so the density


def test_dark_batch_count_is_checkpointed_and_old_checkpoints_load() -> None:
    field = small_field("vm", density_activation="relu", revive_patience=3)
    _fill(field, 1.0, -0.5)
    _dark_batch_grads(field, 2)
    state = field.state_dict()
    assert state["density_relu.dark_batches"].item() == 2
    resumed = small_field("vm", density_activation="relu", revive_patience=3)
    resumed.load_state_dict(state)
    assert (_dark_batch_grads(resumed, 1)[0] < 0).all()  # the third dark batch in a row, across the resume
    assert not state["density_relu.lit"].item()  # dark since its start: the patience still applies
    del state["density_relu.dark_batches"], state["density_relu.lit"]  # a checkpoint from before they existed
    resumed.load_state_dict(state)
    assert resumed.density_relu.dark_batches.item() == 0 and resumed.density_relu.lit.item()


def test_live_relu_field_is_unchanged_by_revival() -> None:
    grads = []
    for revive in (True, False):
        field = small_field("vm", density_activation="relu", revive_dead_density=revive)
        field.prepare(1.0, 1.0)
        sigma = field.density(_points(50))
        assert (sigma > 0).any() and (sigma == 0).any()
        (sigma * torch.arange(50.0)).sum().backward()
        grads.append([p.grad.clone() for p in field.density_grid.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*grads, strict=True))


@pytest.mark.parametrize("feature", [1e4, -1e4, 30.0, -30.0])
def test_density_finite_for_huge_features(feature: float) -> None:
    """Spec 7.2: softplus(x - 10) must stay finite and exact for |x| up to 1e4 (no exp overflow)."""
    field = small_field("vm")
    total = sum(field.config.density_components)
    _fill(field, 1.0, feature / total)
    field.prepare(1.0, 1.0)
    xyz = _points(20).requires_grad_()
    sigma = field.density(xyz)
    assert torch.isfinite(sigma).all() and (sigma >= 0).all()
    expected = float(F.softplus(torch.tensor(feature - 10.0, dtype=torch.float64)))
    assert float(sigma[0].detach()) == pytest.approx(expected, rel=1e-5, abs=1e-30)
    sigma.sum().backward()
    assert torch.isfinite(xyz.grad).all()
    for p in field.density_grid.parameters():
        assert torch.isfinite(p.grad).all()


@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_dc_only_at_f0_gives_constant_density(decomposition: str) -> None:
    field = small_field(decomposition, init_scale=1.0)
    field.prepare(0.0, 0.0)
    sigma = field.density(_points(300))
    torch.testing.assert_close(sigma, sigma[:1].expand_as(sigma), atol=1e-5, rtol=1e-5)
    # With the full band the same field varies in space.
    field.prepare(1.0, 1.0)
    assert float(field.density(_points(300)).detach().std()) > 1e-6


# -------------------------------------------------------------------------------------------------------- colour
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_rgb_shape_range_and_gradients(decomposition: str) -> None:
    field = small_field(decomposition)
    field.prepare(0.6, 0.4)
    xyz = _points(64)
    rgb = field.rgb(xyz, None)
    assert rgb.shape == (64, 3)
    assert ((rgb >= 0) & (rgb <= 1)).all()
    rgb.sum().backward()
    for p in [*field.appearance_grid.parameters(), *field.basis.parameters(), *field.decoder.parameters()]:
        assert p.grad is not None and torch.isfinite(p.grad).all()


def test_rgb_view_dependent_needs_and_uses_directions() -> None:
    field = small_field("vm", view_dependent=True)
    field.prepare(1.0, 1.0)
    xyz = _points(16)
    dirs = F.normalize(torch.randn(16, 3, generator=torch.Generator().manual_seed(5)), dim=-1)
    a, b = field.rgb(xyz, dirs), field.rgb(xyz, -dirs)
    assert not torch.allclose(a, b)
    with pytest.raises(ValueError):
        field.rgb(xyz, None)


def test_rgb_basis_input_width() -> None:
    vm, cp = small_field("vm"), small_field("cp")
    assert vm.basis.in_features == sum(vm.config.appearance_components)
    assert cp.basis.in_features == cp.config.appearance_components[0]
    assert vm.basis.bias is None
