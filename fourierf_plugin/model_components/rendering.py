"""Volume-rendering compositing in a numerically stable form.

Transmittance is ``exp(-exclusive_cumsum(σδ))`` rather than a product of (1 - α) over ~1000 samples: the product
underflows and its gradient degenerates when α ≈ 1, the sum of optical depths does not.
"""

from __future__ import annotations

import torch
from torch import Tensor


def opacity_from_density(sigma: Tensor, step_size: Tensor | float, distance_scale: float = 1.0) -> Tensor:
    """α = 1 − exp(−σ·δ·distance_scale): the alpha of one ray sample (``expm1`` keeps small σ exact)."""
    return -torch.expm1(-sigma * (step_size * distance_scale))


def composite_weights(sigma: Tensor, deltas: Tensor, distance_scale: float = 1.0) -> Tensor:
    """Per-sample weights [R, N] = α_k T_k, with α_k = 1 - exp(-τ_k), T_k = exp(-Σ_{j<k} τ_j), τ = s σ δ.

    Weights lie in [0, 1] and sum to 1 - exp(-Σ τ) ≤ 1 along each ray.
    """
    tau = sigma * deltas * distance_scale
    # Exclusive sum built directly: ``cumsum(tau) - tau`` cancels catastrophically in float32 when a huge τ_k follows
    # small ones (1e5 + 1e-3 - 1e5 = 0), which resets T_k to 1 and lets Σw exceed 1.
    exclusive = torch.cumsum(torch.cat([torch.zeros_like(tau[..., :1]), tau[..., :-1]], dim=-1), dim=-1)
    transmittance = torch.exp(-exclusive)
    alpha = -torch.expm1(-tau)
    return alpha * transmittance


def accumulate(weights: Tensor, values: Tensor, rays: Tensor, num_rays: int) -> Tensor:
    """Weighted sum per ray of packed samples: ``out[r] = Σ_{k: rays[k] = r} weights[k] · values[k]`` -> [R, C].

    Only samples that carry a value need to be listed (the model passes its shaded ones; the rest have colour 0),
    so no [R, N, C] tensor of mostly zeros is built.
    """
    return values.new_zeros(num_rays, values.shape[-1]).index_add(0, rays, weights.unsqueeze(-1) * values)


def blend_background(rgb: Tensor, accumulation: Tensor, background: Tensor) -> Tensor:
    """Composite a ray colour onto the background: ``rgb + (1 - acc) * bg`` (bg [3] or [R, 3])."""
    return rgb + (1.0 - accumulation).unsqueeze(-1) * background


def expected_depth(weights: Tensor, t: Tensor, far: Tensor) -> Tensor:
    """Depth [R] = Σ w t + (1 - acc) · far: misses read as the far end of the ray."""
    acc = weights.sum(dim=-1)
    return (weights * t).sum(dim=-1) + (1.0 - acc) * far


def composite_target(rgba: Tensor, background: Tensor) -> Tensor:
    """Ground truth on the same background as the render: premultiplied rgb + (1 - alpha) · bg."""
    return rgba[..., :3] + (1.0 - rgba[..., 3:4]) * background


def background_color(
    kind: str,
    num_rays: int,
    device: torch.device,
    generator: torch.Generator | None,
    device_generator: torch.Generator | None = None,
) -> Tensor:
    """The training background a scene declared: white, black, a random colour per ray, or — for "none", photos
    that have no background — black or white with even odds per batch, so only full absorption (acc = 1) fits both
    (TensoRF's LLFF trick; on black alone an empty start gets no gradient at all).

    The coin is tossed on the host (``generator``); per-ray colours are drawn where ``device_generator`` lives
    (default: ``generator``), so a GPU step copies nothing."""
    if kind == "none":
        kind = "white" if float(torch.rand(1, generator=generator)) < 0.5 else "black"
    if kind == "white":
        return torch.ones(3, device=device)
    if kind == "black":
        return torch.zeros(3, device=device)
    if kind == "random":
        return random_on(device_generator or generator, (num_rays, 3)).to(device)
    raise ValueError(f"unknown background {kind!r}")


def random_on(generator: torch.Generator | None, shape: tuple[int, ...]) -> Tensor:
    """Uniform [0, 1) numbers drawn where the generator lives (the CPU without one)."""
    return torch.rand(shape, generator=generator, device=generator.device if generator is not None else "cpu")
