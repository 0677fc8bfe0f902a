"""``--help`` says which defaults a run decides for itself (``method_configs.registry.HELP_REGISTRY``) and parsing is
unchanged by it."""

from __future__ import annotations

import re

import pytest
import tyro

from fourierf_plugin.method_configs import AnnotatedMethodUnion, all_methods
from fourierf_plugin.method_configs.budget import RULES
from fourierf_plugin.method_configs.sizing import SIZED_PATHS
from fourierf_plugin.scripts.train import parse_args


def help_text(capsys: pytest.CaptureFixture[str], method: str) -> str:
    with pytest.raises(SystemExit):
        parse_args([method, "--help"])
    return " ".join(re.sub(r"[│╭╮╰╯─]", " ", capsys.readouterr().out).split())


def test_sized_values_read_auto_and_short_run_ones_point_to_the_record(capsys: pytest.CaptureFixture[str]) -> None:
    text = help_text(capsys, "fourierf-vm")
    for path in SIZED_PATHS:
        flag = "--" + path.replace("_", "-")
        assert re.search(
            re.escape(flag) + r" INT (?:(?!--).)*?\(default: auto \(sized to the scene and the device\)", text
        ), path
    short_run = {path for rule in RULES for path in rule.settings} - set(SIZED_PATHS)
    assert text.count("or a short-run default: docs/defaults.md)") == len(short_run)


@pytest.mark.parametrize("method", sorted(all_methods))
def test_the_hints_change_no_parsed_value(method: str) -> None:
    flags = [method, "--pipeline.model.fourier.f0-density", "0.2", "--max-num-iterations", "7"]
    assert parse_args(flags) == tyro.cli(AnnotatedMethodUnion, args=flags)  # type: ignore[arg-type]
