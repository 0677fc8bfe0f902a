"""The viewer is private by default and trusts nothing a page sends: it listens on 127.0.0.1 unless told otherwise,
refuses a websocket from another site's page, sets back any control value the page does not offer, and writes
meshes only inside the run, at a bounded rate and number."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from pathlib import Path

import pytest

from fourierf_plugin.scripts.viewer import ViewerConfig, ViewerHandle, serve
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.viewer.server import MESH_FILES_PER_RUN, check_host, mesh_refusal, open_server
from tests.conftest import require_module

VISER_WHY = "the viewer needs viser (pip install '.[viewer]')"


def non_loopback_address() -> str | None:
    """An IPv4 address of this machine other machines could use (None: it has none)."""
    found: set[str] = set()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("10.255.255.255", 1))  # UDP: no packet is sent, the route picks the interface
            found.add(probe.getsockname()[0])
        except OSError:
            pass
    with contextlib.suppress(OSError):
        found |= {info[4][0] for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)}
    usable = sorted(a for a in found if not a.startswith("127.") and a != "0.0.0.0")
    return usable[0] if usable else None


@pytest.fixture()
def viewer(trained_run) -> ViewerHandle:
    require_module("viser", VISER_WHY)
    _, run_dir = trained_run
    handle = serve(ViewerConfig(load_config=run_dir / "config.json", port=0))  # the default host
    yield handle
    handle.stop()


def test_by_default_the_viewer_is_not_reachable_from_another_address(viewer: ViewerHandle) -> None:
    assert viewer.url == f"http://127.0.0.1:{viewer.port}", "the address it really serves"
    with socket.create_connection(("127.0.0.1", viewer.port), timeout=5):
        pass
    address = non_loopback_address()
    if address is None:
        pytest.skip("this machine has no non-loopback IPv4 address to try")
    with pytest.raises(OSError), socket.create_connection((address, viewer.port), timeout=2):
        pass


def test_listening_on_every_interface_is_warned_about(capsys) -> None:
    require_module("viser", VISER_WHY)
    server = open_server(0, "0.0.0.0")
    try:
        captured = capsys.readouterr()
    finally:
        server.stop()
    err = " ".join(captured.err.split())
    assert "other machines" in err and "--host 127.0.0.1" in err
    assert f"viewer at http://localhost:{server.get_port()}" in captured.out


def test_a_websocket_from_another_sites_page_is_refused(viewer: ViewerHandle) -> None:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    url = f"ws://127.0.0.1:{viewer.port}"
    protocols = [f"viser-v{__import__('viser').__version__}"]
    with pytest.raises(InvalidStatus) as refused:
        connect(url, origin="http://evil.example", subprotocols=protocols, open_timeout=5)
    assert refused.value.response.status_code == 403
    before = viewer.view.client_count
    with connect(url, origin=f"http://127.0.0.1:{viewer.port}", subprotocols=protocols, open_timeout=5):
        pass  # the page's own origin is let in
    assert viewer.view.client_count == before or viewer.view.client_count == before + 1


def send_update(viewer: ViewerHandle, handle, value: object) -> None:
    """What viser does with a page's message that sets a control (no browser attached: no callbacks run)."""
    from viser._messages import GuiUpdateMessage

    gui = viewer.view.server.gui
    asyncio.run(gui._handle_gui_updates(0, GuiUpdateMessage(handle._impl.uuid, {"value": value})))


@pytest.mark.parametrize(
    ("control", "value"),
    [("final", 3000), ("preview", 1), ("density", 5.0), ("density", -1.0), ("colour", float("nan")), ("output", "x")],
)
def test_a_value_the_page_does_not_offer_changes_nothing(viewer: ViewerHandle, control: str, value: object) -> None:
    view = viewer.view
    handle = view._controls[control]
    state = (view.cutoffs(), view.output_name(), view.side(True), view.side(False))
    generation = view._generation
    send_update(viewer, handle, value)
    assert (view.cutoffs(), view.output_name(), view.side(True), view.side(False)) == state
    view._control_moved(control)  # the page's callback, as viser runs it when a browser sent the message
    assert view._generation == generation, "nothing is redrawn"
    assert handle.value != value, "the control is set back to its last valid value"


def test_a_valid_value_from_the_page_is_taken(viewer: ViewerHandle) -> None:
    view = viewer.view
    send_update(viewer, view.final_slider, 512)
    view._control_moved("final")
    assert view.side(True) == 512


def test_meshes_are_paced_and_never_written_through_a_link_out_of_the_run(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    now = time.perf_counter()
    assert mesh_refusal(run, None, now) is None
    assert "wait" in (mesh_refusal(run, now, now + 1) or "")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (run / "meshes").symlink_to(elsewhere)
    assert "link out of the run" in (mesh_refusal(run, None, now) or "")
    (run / "meshes").unlink()
    (run / "meshes").mkdir()
    for n in range(MESH_FILES_PER_RUN):
        (run / "meshes" / f"viewer-f0.500-{n}.ply").write_bytes(b"ply")
    assert "remove some" in (mesh_refusal(run, None, now) or "")


def test_a_second_mesh_at_once_is_refused(viewer: ViewerHandle) -> None:
    view = viewer.view
    view.density_slider.value = 0.5
    first = view.export_mesh()
    assert first is not None and view.export_mesh() is None
    first.unlink()


def test_a_host_that_is_no_address_is_one_clear_error() -> None:
    require_module("viser", VISER_WHY)
    with pytest.raises(UserError, match=r"--viewer-host 'no-such-host\.invalid' is not an address") as info:
        check_host("no-such-host.invalid", "--viewer-host")
    assert "--viewer-host 127.0.0.1" in str(info.value.fix)
