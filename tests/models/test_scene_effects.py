"""What the model builds for each scene effect, through pipelines built the way ``fourierf-train`` builds them.

Blender pipelines must run nothing NDC-specific; LLFF pipelines get NDC rays, a black eval background and FreeNeRF's
occlusion term; ``--pipeline.effects.*`` overrides win over the declaration. Plus the pieces those effects switch on:
the occlusion penalty and its weight, and Floaters-No-More gradient scaling (density and colour gradients scaled in
training only, the forward untouched).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.method_configs.scene_presets import apply_real_scene_preset
from fourierf_plugin.model_components.gradient_scaling import scale_gradient
from fourierf_plugin.model_components.regularisers.floaters import FloatersNoMore
from fourierf_plugin.model_components.regularisers.occlusion import occlusion_penalty
from fourierf_plugin.model_components.rendering import composite_target
from fourierf_plugin.models.fourierf import FourieRFModel, FourieRFModelConfig
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.helpers import TINY_FLAGS, TINY_SCENE, ndc_model

ITERS = 50

OCCLUSION = "fourierf_plugin.model_components.regularisers.occlusion"


def pipeline_for(data: Path, out: Path, *flags: str) -> Pipeline:
    """The pipeline of a tiny run on ``data`` with ``flags``, from the config ``fourierf-train`` would finish."""
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    args = ["fourierf-vm", "--data", str(data), "--output-dir", str(out), "--max-num-iterations", str(ITERS)]
    config, _ = build_config(parse_args([*args, *TINY_FLAGS, *flags, *parser]))
    generator = torch.Generator().manual_seed(0)
    return config.pipeline.setup(device=torch.device("cpu"), max_iters=ITERS, generator=generator)


def forbid(monkeypatch, module: str, name: str) -> None:
    """Make ``module.name`` raise if anything calls it."""

    def forbidden(*args, **kwargs):
        raise AssertionError(f"{name} must not run for this scene")

    monkeypatch.setattr(f"{module}.{name}", forbidden)


def assert_loss_is_the_sum_of_its_terms(metrics: dict) -> None:
    """Every logged term is part of the loss (a regulariser that is logged but not added would pass unseen)."""
    extra = float(metrics["loss"]) - sum(float(v) for k, v in metrics.items() if k not in ("loss", "psnr"))
    assert extra == pytest.approx(0.0, abs=1e-6)


def assert_gradients_reach_the_density_grids(model: FourieRFModel) -> None:
    """Some density parameter has a non-zero gradient, and none has a non-finite one."""
    density = [p.grad for name, p in model.named_parameters() if name.startswith("field.density_grid")]
    assert any(g is not None and bool(g.abs().sum() > 0) for g in density)
    assert all(g is None or bool(torch.isfinite(g).all()) for g in density)


def assert_same_training_batches(data: Path, out: Path, *flags: str, term: str) -> None:
    """With the same parameters, a pipeline with ``flags`` renders the same batches with the same jitter as one
    without (the same MSE to the last bit) over three steps, and logs ``term``: its rays draw from their own stream."""
    torch.manual_seed(0)  # the decoder's layers draw from the global RNG
    plain = pipeline_for(data, out / "plain")
    torch.manual_seed(0)
    on = pipeline_for(data, out / "on", *flags)
    for step in range(3):  # train_step computes the loss only: the parameters stay the same
        _, metrics_plain = plain.train_step(step)
        _, metrics_on = on.train_step(step)
        assert float(metrics_plain["mse"]) == float(metrics_on["mse"]), step
        assert term in metrics_on


# -- pipelines ------------------------------------------------------------------------------------------------------


def test_blender_pipeline_runs_nothing_ndc_specific(tmp_path: Path, monkeypatch) -> None:
    forbid(monkeypatch, "fourierf_plugin.data.datamanager", "ndc_rays")
    forbid(monkeypatch, "fourierf_plugin.models.fourierf", "ndc_samples")
    forbid(monkeypatch, OCCLUSION, "occlusion_penalty")
    pipeline = pipeline_for(TINY_SCENE, tmp_path)
    assert pipeline.effects == SceneEffects("white", "euclidean", False, False) == pipeline.model.effects
    assert pipeline.datamanager.ray_space == "euclidean"
    rays = pipeline.datamanager.train_rays
    torch.testing.assert_close(rays.directions.norm(dim=-1), torch.ones(rays.directions.shape[0]))
    loss, metrics = pipeline.train_step(0)
    assert "occlusion" not in metrics and torch.isfinite(loss)
    view = next(pipeline.render_views("test", 0))
    assert bool(torch.isfinite(view.rgb).all())


def test_llff_pipeline_gets_ndc_rays_a_black_eval_background_and_the_occlusion_term(
    tmp_path: Path, llff_scene: Path, monkeypatch
) -> None:
    forbid(monkeypatch, "fourierf_plugin.models.fourierf", "box_samples")
    pipeline = pipeline_for(llff_scene, tmp_path)
    model = pipeline.model
    assert model.effects == SceneEffects("none", "ndc", False, True) == pipeline.effects
    assert pipeline.datamanager.ray_space == "ndc"
    rays = pipeline.datamanager.train_rays
    torch.testing.assert_close(rays.origins[:, 2], torch.full_like(rays.origins[:, 2], -1.0))
    torch.testing.assert_close(rays.directions[:, 2], torch.full_like(rays.directions[:, 2], 2.0))

    model.prepare(0)
    out = model.train()(rays.origins[:64], rays.directions[:64])
    assert "occlusion" in out and math.isfinite(out["occlusion"].item())
    bg = out["background"]
    assert bool((bg == 0).all() or (bg == 1).all()), "photos (background none) train on black or white per batch"
    loss, metrics = pipeline.train_step(0)
    assert "occlusion" in metrics and math.isfinite(metrics["occlusion"]) and torch.isfinite(loss)

    assert model.effects.eval_background == "black"
    with torch.no_grad():
        assert torch.equal(model.eval()(rays.origins[:8], rays.directions[:8])["background"], torch.zeros(3))
    view = next(pipeline.render_views("test", 0))
    assert bool(torch.isfinite(view.rgb).all()) and tuple(view.rgb.shape) == (6, 8, 3)
    target = composite_target(view.view.rays.rgba, torch.zeros(3)).view(6, 8, 3)
    torch.testing.assert_close(view.target, target)


def test_the_occlusion_override_removes_the_term(tmp_path: Path, llff_scene: Path, monkeypatch) -> None:
    forbid(monkeypatch, OCCLUSION, "occlusion_penalty")
    pipeline = pipeline_for(llff_scene, tmp_path, "--pipeline.effects.occlusion-regularization", "False")
    _, metrics = pipeline.train_step(0)
    assert "occlusion" not in metrics
    assert pipeline.model.effects == SceneEffects("none", "ndc", False, False), "the other declared effects stay"


def test_the_background_override_reaches_training_and_eval(tmp_path: Path, llff_scene: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path, "--pipeline.effects.background", "white")
    rays = pipeline.datamanager.train_rays
    model = pipeline.model
    model.prepare(0)
    for mode in (model.train(), model.eval()):
        with torch.no_grad():
            assert bool((mode(rays.origins[:8], rays.directions[:8])["background"] == 1).all())


def test_the_view_dependence_override_gives_the_field_view_directions(tmp_path: Path, llff_scene: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path, "--pipeline.effects.view-dependent", "True")
    assert pipeline.model.effects.view_dependent and pipeline.model.field.decoder.view_dependent
    seen = []
    rgb = pipeline.model.field.rgb
    pipeline.model.field.rgb = lambda xyz, dirs: seen.append(dirs) or rgb(xyz, dirs)  # type: ignore[method-assign]
    pipeline.train_step(0)
    assert seen and all(d is not None for d in seen)
    torch.testing.assert_close(seen[0].norm(dim=-1), torch.ones(seen[0].shape[0]))


# Regression: with a plain black background and softplus(x - 10) densities, every weight of a fresh LLFF model is
# below the 1e-4 shading threshold, so no colour is evaluated and d rgb / d w = c - bg = 0: the photometric loss gave
# the density grid exactly zero gradient and training never started. Photos now declare background "none" (trained
# on black or white at random per batch, TensoRF's LLFF term), which gives the density a gradient from step 0.
def test_fresh_llff_model_learns_a_constant_colour() -> None:
    """80 steps on a grey target seen by a camera at the origin: the (black-evaluated) render must turn grey."""
    config = copy.deepcopy(all_methods["fourierf-vm"])
    apply_real_scene_preset(config, all_methods["fourierf-vm"])  # what finalize does on a forward-facing scene
    m = config.pipeline.model
    m.field.n_voxels_init = m.field.n_voxels_final = 4096
    m.field.upsample_fractions, m.occupancy_update_fractions = (), ()
    torch.manual_seed(0)
    model = ndc_model(m, max_iters=1000)
    optimizer = build_optimizer(config.optimizer, model.param_groups())
    origins, directions = parallel_ndc_rays(256)
    target = torch.cat([torch.full((256, 3), 0.5), torch.ones(256, 1)], dim=-1)
    model.train()
    for step in range(80):
        model.prepare(step)
        loss = torch.stack(list(model.loss_dict(model(origins, directions), target, step).values()))
        optimizer.zero_grad()
        loss.sum().backward()
        optimizer.step()
    rgb = model.render_rays(origins, directions, 80)["rgb"]
    mse = float(((rgb - 0.5) ** 2).mean())
    assert mse < 0.01, f"after 80 steps the render is still {rgb.mean():.3f} on average (mse {mse:.3f} to grey)"


def parallel_ndc_rays(n: int, seed: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """NDC rays of a camera at the origin looking down -z: parallel, o' on the near face, d' = (0, 0, 2)."""
    g = torch.Generator().manual_seed(seed)
    origins = torch.cat([(torch.rand(n, 2, generator=g) - 0.5) * 2, -torch.ones(n, 1)], dim=-1)
    return origins, torch.tensor([[0.0, 0.0, 2.0]]).expand(n, 3)


# -- occlusion penalty ----------------------------------------------------------------------------------------------


def test_the_models_occlusion_term_follows_its_distance_scale() -> None:
    """Same σ (same seeded jitter), twice the distance scale: twice the occlusion term; 25× the raw-σ term at 25."""
    field = FieldConfig(n_voxels_init=4096, n_voxels_final=13824, density_activation="relu")
    terms, sigmas = [], []
    for scale in (25.0, 50.0):
        model = ndc_model(FourieRFModelConfig(field=field, distance_scale=scale))
        march = model.march
        model.march = lambda samples, march=march: sigmas.append(march(samples)) or sigmas[-1]  # type: ignore[method-assign]
        model.prepare(0)
        terms.append(model.train()(*parallel_ndc_rays(16))["occlusion"])
    torch.testing.assert_close(sigmas[0], sigmas[1])
    assert terms[0].item() > 0, "precondition: the fresh field has density in front of the cameras"
    torch.testing.assert_close(terms[1], 2 * terms[0])
    torch.testing.assert_close(terms[0], 25.0 * occlusion_penalty(sigmas[0], 20 / 128, 1.0))


def test_occlusion_penalty_weight_in_the_loss(tmp_path: Path, llff_scene: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path)
    model = pipeline.model
    rays = pipeline.datamanager.train_rays
    model.prepare(0)
    out = model.train()(rays.origins[:32], rays.directions[:32])
    terms = model.loss_dict(out, rays.rgba[:32], 0)
    torch.testing.assert_close(terms["occlusion"], model.config.occlusion_weight * out["occlusion"])
    assert model.config.occlusion_weight == 0.01


def test_no_occlusion_term_at_eval() -> None:
    model = ndc_model(FourieRFModelConfig(field=FieldConfig(n_voxels_init=4096, n_voxels_final=13824)))
    model.prepare(0)
    with torch.no_grad():
        assert "occlusion" not in model.eval()(*parallel_ndc_rays(4))


# -- gradient scaling -----------------------------------------------------------------------------------------------


def test_scale_gradient_is_identity_forward_and_scales_backward() -> None:
    x = torch.tensor([1.0, -2.0, 3.0], requires_grad=True)
    scale = torch.tensor([0.5, 0.0, 1.0])
    y = scale_gradient(x, scale)
    assert torch.equal(y.detach(), x.detach())
    (y * torch.tensor([1.0, 2.0, 3.0])).sum().backward()
    torch.testing.assert_close(x.grad, torch.tensor([0.5, 0.0, 3.0]))


def test_scale_gradient_broadcasts_over_colour_channels() -> None:
    x = torch.ones(2, 3, 3, requires_grad=True)
    scale = torch.tensor([[0.25, 1.0, 0.0], [1.0, 1.0, 0.5]]).unsqueeze(-1)
    scale_gradient(x, scale).sum().backward()
    torch.testing.assert_close(x.grad, scale.expand(2, 3, 3))


def floaters_model(floaters: bool, start: float = 0.0) -> FourieRFModel:
    # density_shift 0 gives softplus(raw) ~ 0.7: enough weight on every sample that colours are shaded too
    cfg = FourieRFModelConfig(
        field=FieldConfig(n_voxels_init=4096, n_voxels_final=13824, density_shift=0.0),
        floaters_gradient_scaling=floaters,
        floaters_gradient_scaling_from=start,
    )
    torch.manual_seed(0)  # the decoder's layers draw from the global RNG
    return ndc_model(cfg)


def grads(
    floaters: bool, training: bool, start: float = 0.0, step: int = 0
) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """Parameter gradients of an MSE on 128 NDC rays at ``step`` (same rays, same jitter with and without
    scaling)."""
    model = floaters_model(floaters, start)
    g = torch.Generator().manual_seed(1)
    origins = torch.cat([(torch.rand(128, 2, generator=g) - 0.5) * 2, -torch.ones(128, 1)], dim=-1)
    directions = torch.cat([(torch.rand(128, 2, generator=g) - 0.5) * 0.2, torch.full((128, 1), 2.0)], dim=-1)
    target = torch.rand(128, 3, generator=g)
    model.prepare(step)
    out = model.train(training)(origins, directions)
    ((out["rgb"] - target) ** 2).mean().backward()
    found = {name: p.grad.detach().clone() for name, p in model.named_parameters() if p.grad is not None}
    return found, out["rgb"].detach()


def test_floaters_scaling_reaches_density_and_colour() -> None:
    """Same batch and jitter with and without: identical forward, different density AND appearance gradients."""
    plain, rgb_plain = grads(False, training=True)
    scaled, rgb_scaled = grads(True, training=True)
    torch.testing.assert_close(rgb_plain, rgb_scaled, rtol=0, atol=0)
    assert plain.keys() == scaled.keys()
    density = [n for n in plain if n.startswith("field.density_grid")]
    appearance = [n for n in plain if n.startswith("field.appearance_grid")]
    assert density and appearance
    for names, what in ((density, "density"), (appearance, "appearance")):
        for n in names:
            assert torch.isfinite(scaled[n]).all()
        assert any(not torch.allclose(plain[n], scaled[n]) for n in names), f"{what} gradients are not scaled"
    # every NDC sample has t < 1, so the scale t² < 1 shrinks the total gradient
    total = lambda g: sum(float(v.norm() ** 2) for v in g.values())  # noqa: E731
    assert total(scaled) < total(plain)


def test_floaters_scaling_is_off_by_default_and_at_eval() -> None:
    """At eval (no jitter) the same rays give the same colours and exactly the same gradients with the flag on."""
    assert FourieRFModelConfig().floaters_gradient_scaling is False
    plain, rgb_plain = grads(False, training=False)
    scaled, rgb_scaled = grads(True, training=False)
    assert torch.equal(rgb_plain, rgb_scaled)
    assert plain.keys() == scaled.keys() and plain
    for name, grad in plain.items():
        assert torch.equal(scaled[name], grad), name


def test_floaters_scaling_starts_at_its_fraction_of_the_run() -> None:
    """With the scaling from half the run: before that step the gradients are the plain ones to the bit, from it on
    they are the scaled ones (the same as scaling the whole run)."""
    model = floaters_model(True, start=0.5)
    (floaters,) = [r for r in model.regularisers if isinstance(r, FloatersNoMore)]
    half = floaters.from_step
    assert half == round(0.5 * model.max_iters) > 0
    scaling = [bool(model.gradient_scalers_at(s)) for s in (0, half - 1, half, model.max_iters)]
    assert scaling == [False, False, True, True]
    for step, reference in ((half - 1, False), (half, True)):
        late, _ = grads(True, training=True, start=0.5, step=step)
        same, _ = grads(reference, training=True, step=step)
        assert late.keys() == same.keys() and late
        for name, grad in same.items():
            assert torch.equal(late[name], grad), (step, name)
