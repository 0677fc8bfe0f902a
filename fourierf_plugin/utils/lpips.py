"""LPIPS v0.1 (AlexNet backbone) in plain torch, loaded from a converted state dict.

The project avoids torchvision and the ``lpips`` package, so the network is rebuilt here: AlexNet's five conv layers
with ReLU taps taken before the max-pools, unit-normalised channel features, squared differences weighted by 1x1
linear heads, spatial mean, summed over taps. The weights file is described in ``../shared/README.md``.
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from fourierf_plugin.utils.errors import UserError

WEIGHTS_NAME = "lpips_alex_v0.1.pth"
WEIGHTS_ENV = "FOURIERF_LPIPS_WEIGHTS"

# AlexNet conv1..conv5 as in torchvision's alexnet.features, which LPIPS slices into its five taps.
_CONV_IN_OUT = ((3, 64), (64, 192), (192, 384), (384, 256), (256, 256))
_CONV_KERNEL = (11, 5, 3, 3, 3)
_CONV_STRIDE = (4, 1, 1, 1, 1)
_CONV_PADDING = (2, 2, 1, 1, 1)
_POOL_AFTER = (True, True, False, False, False)  # max-pool 3/2 after the conv1 and conv2 taps
_NORM_EPS = 1e-10


def _expected_shapes() -> dict[str, tuple[int, ...]]:
    shapes: dict[str, tuple[int, ...]] = {"shift": (1, 3, 1, 1), "scale": (1, 3, 1, 1)}
    for i, ((cin, cout), k) in enumerate(zip(_CONV_IN_OUT, _CONV_KERNEL, strict=True)):
        shapes[f"convs.{i}.weight"] = (cout, cin, k, k)
        shapes[f"convs.{i}.bias"] = (cout,)
        shapes[f"lins.{i}.weight"] = (1, cout, 1, 1)
    return shapes


def _load_state_dict(path: Path) -> dict[str, torch.Tensor]:
    fix_missing = f"pass --lpips-weights PATH pointing at {WEIGHTS_NAME}, or keep ../shared/lpips beside the clone"
    if not path.is_file():
        raise UserError(f"LPIPS weights file {path} does not exist", fix_missing)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # unpickling errors come in many types; all mean "not a usable weights file"
        raise UserError(
            f"LPIPS weights file {path} could not be read as a torch state dict ({type(err).__name__}: {err})",
            f"pass --lpips-weights PATH pointing at an intact {WEIGHTS_NAME}",
        ) from err
    if not isinstance(state, dict):
        raise UserError(
            f"LPIPS weights file {path} holds a {type(state).__name__}, not a state dict",
            f"pass --lpips-weights PATH pointing at {WEIGHTS_NAME}",
        )
    expected = _expected_shapes()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    wrong = sorted(
        k
        for k in set(expected) & set(state)
        if not isinstance(state[k], torch.Tensor) or tuple(state[k].shape) != expected[k]
    )
    if missing or unexpected or wrong:
        details = "; ".join(
            f"{label}: {', '.join(keys[:6])}{' ...' if len(keys) > 6 else ''}"
            for label, keys in (("missing", missing), ("unexpected", unexpected), ("wrong shape", wrong))
            if keys
        )
        raise UserError(
            f"LPIPS weights file {path} is not an LPIPS v0.1 AlexNet state dict ({details})",
            f"pass --lpips-weights PATH pointing at {WEIGHTS_NAME} from ../shared/lpips",
        )
    return {k: state[k].to(torch.float32) for k in expected}


def _normalize_channels(x: torch.Tensor) -> torch.Tensor:
    return x / (torch.sqrt(torch.sum(x * x, dim=1, keepdim=True)) + _NORM_EPS)


class LPIPS(nn.Module):
    """LPIPS-alex v0.1 distance; frozen, eval mode, inputs in [0, 1] (the ``lpips`` package's ``normalize=True``)."""

    def __init__(self, weights_path: Path) -> None:
        super().__init__()
        state = _load_state_dict(Path(weights_path))
        self.register_buffer("shift", state["shift"])
        self.register_buffer("scale", state["scale"])
        self.convs = nn.ModuleList(
            nn.Conv2d(cin, cout, k, stride=s, padding=p)
            for (cin, cout), k, s, p in zip(_CONV_IN_OUT, _CONV_KERNEL, _CONV_STRIDE, _CONV_PADDING, strict=True)
        )
        self.lins = nn.ModuleList(nn.Conv2d(cout, 1, 1, bias=False) for _, cout in _CONV_IN_OUT)
        self.load_state_dict(state)
        self.requires_grad_(False)
        self.eval()

    def _features(self, x: torch.Tensor) -> list[torch.Tensor]:
        taps = []
        for conv, pool in zip(self.convs, _POOL_AFTER, strict=True):
            x = F.relu(conv(x))
            taps.append(x)
            if pool:
                x = F.max_pool2d(x, kernel_size=3, stride=2)
        return taps

    def forward(self, img0: torch.Tensor, img1: torch.Tensor) -> torch.Tensor:
        """Distances ``[B]`` between ``[B, 3, H, W]`` batches in [0, 1]."""
        if img0.shape != img1.shape or img0.ndim != 4 or img0.shape[1] != 3:
            raise ValueError(f"LPIPS expects two [B, 3, H, W] tensors, got {tuple(img0.shape)} and {tuple(img1.shape)}")
        dtype = self.shift.dtype
        x0 = ((img0.to(dtype) * 2 - 1) - self.shift) / self.scale
        x1 = ((img1.to(dtype) * 2 - 1) - self.shift) / self.scale
        total = torch.zeros(img0.shape[0], dtype=dtype, device=img0.device)
        for f0, f1, lin in zip(self._features(x0), self._features(x1), self.lins, strict=True):
            diff = (_normalize_channels(f0) - _normalize_channels(f1)) ** 2
            total = total + lin(diff).mean(dim=(1, 2, 3))
        return total

    @torch.no_grad()
    def distance(self, pred_hwc: torch.Tensor, gt_hwc: torch.Tensor) -> float:
        """LPIPS between two ``[H, W, 3]`` images in [0, 1]."""
        device = self.shift.device
        p = pred_hwc.detach().to(device).permute(2, 0, 1).unsqueeze(0)
        g = gt_hwc.detach().to(device).permute(2, 0, 1).unsqueeze(0)
        return float(self(p, g)[0])


def default_lpips_weights() -> Path | None:
    """Where the weights live by default: $FOURIERF_LPIPS_WEIGHTS, then ../shared/lpips beside the repo or the cwd."""
    candidates: list[Path] = []
    env = os.environ.get(WEIGHTS_ENV, "")
    if env:
        candidates.append(Path(env).expanduser())
    repo_root = Path(__file__).resolve().parents[2]
    candidates.append(repo_root.parent / "shared" / "lpips" / WEIGHTS_NAME)
    candidates.append(Path.cwd().parent / "shared" / "lpips" / WEIGHTS_NAME)
    for path in candidates:
        if path.is_file():
            return path
    return None
