"""The FourieRF field: filtered-grid cache, coordinate normalisation, density and colour (spec 3.1, 4.4, 7.2, 7.10)."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig, FourierTensoRFField, use_bfloat16

AABB = torch.tensor([[-1.5, -0.5, 0.0], [1.5, 2.5, 1.0]])
RESO = [5, 7, 9]


def _field(decomposition: str = "vm", view_dependent: bool = False, **kw: object) -> FourierTensoRFField:
    comps = (4, 3, 2) if decomposition == "vm" else (5, 5, 5)
    cfg = FieldConfig(
        decomposition=decomposition,  # type: ignore[arg-type]
        density_components=comps,
        appearance_components=comps,
        appearance_dim=6,
        hidden_dim=8,
        **kw,  # type: ignore[arg-type]
    )
    return FourierTensoRFField(cfg, AABB, list(RESO), view_dependent, torch.Generator().manual_seed(0))


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
    field = _field(decomposition)
    g = field.filtered_grids(1.0, 1.0)
    assert all(a is b for a, b in zip(g.density_planes, field.density_grid.planes, strict=True))
    assert all(a is b for a, b in zip(g.density_lines, field.density_grid.lines, strict=True))
    assert all(a is b for a, b in zip(g.appearance_planes, field.appearance_grid.planes, strict=True))
    assert all(a is b for a, b in zip(g.appearance_lines, field.appearance_grid.lines, strict=True))
    assert len(g.density_lines) == 3
    assert len(g.density_planes) == (3 if decomposition == "vm" else 0)


def test_lookup_before_prepare_raises() -> None:
    field = _field()
    xyz = _points(4)
    with pytest.raises(RuntimeError, match="prepare"):
        field.density(xyz)
    with pytest.raises(RuntimeError, match="prepare"):
        field.rgb(xyz, None)


def test_invalidate_then_lookup_raises() -> None:
    field = _field()
    field.prepare(1.0, 1.0)
    field.density(_points(4))
    field.invalidate()
    with pytest.raises(RuntimeError):
        field.density(_points(4))
    with pytest.raises(RuntimeError):
        _ = field.filtered


def test_prepare_caches_one_filtering_per_call() -> None:
    field = _field()
    field.prepare(0.3, 0.5)
    first = field.filtered
    assert field.filtered is first  # every lookup of the iteration reuses it
    field.prepare(0.3, 0.5)
    assert field.filtered is not first


def test_app_planes_follow_density_cutoff() -> None:
    field = _field()
    g = field.filtered_grids(0.0, 1.0, app_planes_follow_density=True)
    for p in g.appearance_planes:  # f = 0 on planes: the plane mean only
        torch.testing.assert_close(p, p.mean(dim=(-2, -1), keepdim=True).expand_as(p), atol=1e-6, rtol=0)
    assert all(a is b for a, b in zip(g.appearance_lines, field.appearance_grid.lines, strict=True))


def test_filtered_grids_carry_gradients_to_raw_parameters() -> None:
    field = _field()
    field.prepare(0.5, 0.5)
    xyz = _points(32)
    (field.density(xyz).sum() + field.rgb(xyz, None).sum()).backward()
    for name, p in field.named_parameters():
        assert p.grad is not None, name
        assert torch.isfinite(p.grad).all(), name
    assert any(float(p.grad.abs().sum()) > 0 for p in field.density_grid.parameters())


# --------------------------------------------------------------------------------------------------- geometry
def test_normalize_maps_box_corners_to_unit_cube() -> None:
    field = _field()
    corners = torch.tensor([[AABB[i, 0], AABB[j, 1], AABB[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    x = field.normalize(corners)
    expected = torch.tensor([[i, j, k] for i in (-1.0, 1.0) for j in (-1.0, 1.0) for k in (-1.0, 1.0)])
    torch.testing.assert_close(x, expected, atol=1e-6, rtol=0)
    torch.testing.assert_close(field.normalize(AABB.mean(dim=0, keepdim=True)), torch.zeros(1, 3), atol=1e-6, rtol=0)


def test_resolution_and_aabb_buffer() -> None:
    field = _field()
    assert field.resolution == RESO
    assert "aabb" in dict(field.named_buffers())
    assert torch.equal(field.aabb, AABB)


# ------------------------------------------------------------------------------------------------------ density
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_density_nonnegative_finite(decomposition: str) -> None:
    field = _field(decomposition)
    field.prepare(1.0, 1.0)
    sigma = field.density(_points(200))
    assert sigma.shape == (200,)
    assert torch.isfinite(sigma).all() and (sigma >= 0).all()


@pytest.mark.parametrize("a", [0.0, 0.5, -0.7, 2.0])
def test_density_softplus_shift_exact_vm(a: float) -> None:
    """planes = 1, lines = a: the σ feature is Σ_i C_i · a, and σ = softplus(feature - 10) everywhere."""
    field = _field("vm")
    _fill(field, 1.0, a)
    field.prepare(1.0, 1.0)
    feature = sum(field.config.density_components) * a
    expected = F.softplus(torch.tensor(feature - 10.0))
    sigma = field.density(_points(50))
    torch.testing.assert_close(sigma, expected.expand(50), atol=1e-7, rtol=1e-6)


def test_density_cp_feature_is_sum_of_products() -> None:
    field = _field("cp")
    with torch.no_grad():
        for value, line in zip((2.0, 0.5, 3.0), field.density_grid.lines, strict=True):
            line.fill_(value)
    field.prepare(1.0, 1.0)
    expected = F.softplus(torch.tensor(5 * 2.0 * 0.5 * 3.0 - 10.0))
    torch.testing.assert_close(field.density(_points(20)), expected.expand(20), atol=1e-7, rtol=1e-6)


def test_density_relu_activation() -> None:
    field = _field("vm", density_activation="relu")
    _fill(field, 1.0, 2.0)  # feature = 9 * 2 = 18 -> relu(18) = 18: ReLU takes no shift (TensoRF)
    field.prepare(1.0, 1.0)
    torch.testing.assert_close(field.density(_points(10)), torch.full((10,), 18.0))
    _fill(field, 1.0, -0.5)  # feature -4.5 -> relu(-4.5) = 0 (the "dead" LLFF case, spec 7.2)
    field.prepare(1.0, 1.0)
    assert (field.density(_points(10)) == 0).all()


@pytest.mark.parametrize("feature", [1e4, -1e4, 30.0, -30.0])
def test_density_finite_for_huge_features(feature: float) -> None:
    """Spec 7.2: softplus(x - 10) must stay finite and exact for |x| up to 1e4 (no exp overflow)."""
    field = _field("vm")
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
    field = _field(decomposition, init_scale=1.0)
    field.prepare(0.0, 0.0)
    sigma = field.density(_points(300))
    torch.testing.assert_close(sigma, sigma[:1].expand_as(sigma), atol=1e-5, rtol=1e-5)
    # With the full band the same field varies in space.
    field.prepare(1.0, 1.0)
    assert float(field.density(_points(300)).detach().std()) > 1e-6


# -------------------------------------------------------------------------------------------------------- colour
@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_rgb_shape_range_and_gradients(decomposition: str) -> None:
    field = _field(decomposition)
    field.prepare(0.6, 0.4)
    xyz = _points(64)
    rgb = field.rgb(xyz, None)
    assert rgb.shape == (64, 3)
    assert ((rgb >= 0) & (rgb <= 1)).all()
    rgb.sum().backward()
    for p in [*field.appearance_grid.parameters(), *field.basis.parameters(), *field.decoder.parameters()]:
        assert p.grad is not None and torch.isfinite(p.grad).all()


def test_rgb_view_dependent_needs_and_uses_directions() -> None:
    field = _field("vm", view_dependent=True)
    field.prepare(1.0, 1.0)
    xyz = _points(16)
    dirs = F.normalize(torch.randn(16, 3, generator=torch.Generator().manual_seed(5)), dim=-1)
    a, b = field.rgb(xyz, dirs), field.rgb(xyz, -dirs)
    assert not torch.allclose(a, b)
    with pytest.raises(ValueError):
        field.rgb(xyz, None)


def test_rgb_basis_input_width() -> None:
    vm, cp = _field("vm"), _field("cp")
    assert vm.basis.in_features == sum(vm.config.appearance_components)
    assert cp.basis.in_features == cp.config.appearance_components[0]
    assert vm.basis.bias is None


# -- decoder precision ------------------------------------------------------------------------------------------------
def _rgb_with(precision: str, xyz: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
    torch.manual_seed(0)  # the decoder's layers draw from the global generator
    field = _field(decoder_precision=precision)
    field.prepare(1.0, 1.0)
    rgb = field.rgb(xyz, None)
    rgb.sum().backward()
    return rgb.detach(), [p.grad for p in field.parameters() if p.grad is not None]


def test_bfloat16_decoder_matches_float32_to_its_precision_with_finite_gradients() -> None:
    xyz = torch.rand(500, 3, generator=torch.Generator().manual_seed(2)) * 2 - 1
    ref, _ = _rgb_with("float32", xyz)
    low, grads = _rgb_with("bfloat16", xyz)
    assert low.dtype == torch.float32
    err = (low - ref).abs().max().item()
    assert 0 < err < 1e-2, err  # it did run in bf16 (not bit-equal) and stays within a few bf16 ulps of a colour
    assert grads and all(bool(torch.isfinite(g).all()) for g in grads)


def test_auto_precision_is_for_renders_on_bf16_cpus_and_never_downcasts_float64() -> None:
    f32 = torch.zeros(2, 3)
    assert not use_bfloat16("auto", f32), "training (gradients on) stays float32 under auto"
    with torch.no_grad():
        assert use_bfloat16("auto", f32) == bool(torch.cpu._is_avx512_bf16_supported())
    assert use_bfloat16("bfloat16", f32) and not use_bfloat16("float32", f32)
    assert not use_bfloat16("bfloat16", f32.double())


# ------------------------------------------------------------------------------------------------ dense tables
def _outputs(field: FourierTensoRFField, xyz: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    field.prepare(0.6, 0.8)
    return field.density(xyz), field.rgb(xyz, None)


def _baked(field: FourierTensoRFField) -> set[str]:
    return {kind for kind, table in field.filtered.dense.items() if table is not None}


def test_dense_tables_follow_the_budgets_and_read_the_same_field() -> None:
    """Training bakes only the density (differentiably) up to a vertex count; renders bake both tables within a MB
    budget; every combination gives the factored lookup's density and colour."""
    xyz = _points(200)
    torch.manual_seed(0)
    factored = _field(decoder_precision="float32", dense_train_max_vertices=0, dense_render_max_mb=0)
    with torch.no_grad():
        reference = _outputs(factored, xyz)
    assert factored.filtered.dense == {"density": None, "appearance": None}
    for train_max, render_mb, train_kinds, render_kinds in [
        (10**6, 1.0, {"density"}, {"density", "appearance"}),
        (10, 315 * 4 / 2**20, set(), {"density"}),  # 315 vertices: the density fits, 6 appearance channels do not
    ]:
        torch.manual_seed(0)
        field = _field(decoder_precision="float32", dense_train_max_vertices=train_max, dense_render_max_mb=render_mb)
        density, rgb = _outputs(field, xyz)
        assert _baked(field) == train_kinds
        torch.testing.assert_close(density.detach(), reference[0], atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(rgb.detach(), reference[1], atol=1e-6, rtol=1e-5)
        with torch.no_grad():
            density, rgb = _outputs(field, xyz)
        assert _baked(field) == render_kinds
        torch.testing.assert_close(density, reference[0], atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(rgb, reference[1], atol=1e-6, rtol=1e-5)


def test_dense_density_in_training_gives_finite_gradients_to_every_factor() -> None:
    field = _field(dense_train_max_vertices=10**6)
    field.prepare(0.4, 0.4)
    field.density(_points(64)).sum().backward()
    assert _baked(field) == {"density"}
    for p in field.density_grid.parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all()
        assert float(p.grad.abs().sum()) > 0


def test_renders_reuse_the_tables_until_a_parameter_or_cutoff_changes() -> None:
    field = _field()
    with torch.no_grad():
        field.prepare(0.5, 0.5)
        first = field.filtered
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
    field.prepare(0.6, 0.5)  # training always filters afresh, with a graph
    assert field.filtered is not third and field.filtered.density_planes[0].requires_grad


def test_tables_are_built_at_the_first_lookup_of_their_kind_only() -> None:
    """A prepare that only reads the factors (an upsample) or only the density (an occupancy update) bakes no
    appearance table: the biggest one."""
    field = _field()
    with torch.no_grad():
        field.prepare(0.5, 0.5)
        assert field.filtered.dense == {}
        field.density(_points(8))
        assert _baked(field) == {"density"}
        field.rgb(_points(8), None)
        assert _baked(field) == {"density", "appearance"}
