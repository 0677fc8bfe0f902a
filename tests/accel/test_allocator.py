"""The allocator tuning every console script applies: on glibc it takes, elsewhere it is a no-op."""

from __future__ import annotations

import ctypes.util
import platform
import sys

import pytest

from fourierf_plugin.accel.allocator import keep_freed_memory


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc", reason="mallopt is glibc-only"
)
def test_glibc_accepts_the_settings_and_they_can_be_applied_twice() -> None:
    assert ctypes.util.find_library("c") is not None
    assert keep_freed_memory() is True
    assert keep_freed_memory() is True


def test_non_linux_is_a_no_op(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "darwin")
    assert keep_freed_memory() is False


def test_a_libc_without_mallopt_is_a_no_op(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    assert keep_freed_memory() is False
