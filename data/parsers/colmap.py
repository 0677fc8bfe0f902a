"""``colmap-data``: a COLMAP sparse model and its photos, e.g. the output of the COLMAP binary, of ``ns-process-data``
or of ``fourierf-process-data``.

Only the reading is here (our own readers of the binary and text formats, so ``pycolmap`` is not needed to train);
normalisation, splits, view selection and the scene's effects are the capture base's, as for ``nerfstudio-data``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from fourierf_plugin.data.capture import Capture
from fourierf_plugin.data.colmap_model import capture_from_model, read_model
from fourierf_plugin.data.dataparser_transforms import DataparserTransform
from fourierf_plugin.data.parsers.capture_parser import CaptureParser, CaptureParserConfig
from fourierf_plugin.utils.errors import fail

DEFAULT_COLMAP_PATH = Path("colmap/sparse/0")
FALLBACK_COLMAP_PATHS = (Path("sparse/0"), Path("sparse"))
"""Where the model is looked for when ``--colmap-path`` keeps its default: nerfstudio's layout, then COLMAP's."""


class ColmapDataParser(CaptureParser):
    """Reads ``data/<colmap_path>`` and the photos in ``data/<images_path>``."""

    config: ColmapDataParserConfig

    def model_folder(self) -> Path:
        """The model folder: ``--colmap-path`` when it exists; with the default, also the usual fallbacks."""
        data = Path(self.config.data)
        if not data.is_dir():
            fail(
                f"data folder not found: {data}",
                "pass --data pointing at the scene folder (holding colmap/ or sparse/)",
            )
        chosen = Path(self.config.colmap_path)
        tried = [chosen] if chosen != DEFAULT_COLMAP_PATH else [chosen, *FALLBACK_COLMAP_PATHS]
        for rel in tried:
            folder = rel if rel.is_absolute() else data / rel
            if (folder / "cameras.bin").is_file() or (folder / "cameras.txt").is_file():
                return folder
        names = ", ".join(str(rel) for rel in tried)
        fix = (
            "run fourierf-process-data images --data PHOTOS --output-dir SCENE first, or pass --colmap-path "
            "pointing at the model folder (the one holding cameras.bin, images.bin, points3D.bin)"
        )
        if (data / "transforms.json").is_file():
            fix = f"{data} has a transforms.json: use nerfstudio-data, or pass --colmap-path"
        fail(f"no COLMAP model in {data} (looked in {names})", fix)

    def read_capture(self) -> Capture:
        folder = self.model_folder()
        images = Path(self.config.images_path)
        return capture_from_model(
            read_model(folder), images if images.is_absolute() else Path(self.config.data) / images
        )

    def dataparser_transform(self) -> DataparserTransform | None:
        """From the COLMAP model's own world frame, so a mesh overlays its points (the poses are read into
        nerfstudio's turned frame first, ``applied_transform``)."""
        inner = super().dataparser_transform()
        applied = self.capture().applied_transform
        return inner if inner is None or applied is None else inner.after(applied)


@dataclass
class ColmapDataParserConfig(CaptureParserConfig):
    """A COLMAP sparse model (binary or text) with its photos: object-centric or forward-facing, decided per scene."""

    _target: ClassVar[type] = ColmapDataParser

    colmap_path: Path = DEFAULT_COLMAP_PATH
    """The sparse model folder, relative to --data (default: colmap/sparse/0, then sparse/0, then sparse)."""
    images_path: Path = Path("images")
    """The photos COLMAP ran on, relative to --data."""
