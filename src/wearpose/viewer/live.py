"""Browser viewer built on `viser <https://viser.studio>`_ (three.js client bundled with the
package and served from localhost: nothing is downloaded).

Two entry points share one scene description (:class:`BodyLayer`):

- :class:`RecordingViewer` (offline): a recording's ground truth and/or an estimated
  :class:`~wearpose.estimators.PoseTrack`, side by side, with a timeline (frame slider,
  play/pause, speed).
- :class:`LiveViewer` (live): subscribes to a :class:`wearpose.stream.StreamServer` and shows
  every subject's latest pose; the timeline scrubs back through the last ``history_s`` seconds.

Each body is drawn as a skinned mesh (linear blend skinning in the browser, same maths as
:class:`~wearpose.body.BodyModel` without pose correctives), its skeleton (bones as lines,
joints as points coloured by per-joint uncertainty when the estimator gives one) and its
sensors at their body sites: green valid, red dropped (masked) in that frame, and shaded
green -> orange -> red by an interference level in [0, 1] when the pose carries
``extras["interference"]`` (one value per sensor).

Origin check: viser (1.1) has no option to refuse a foreign browser page, so :class:`OriginGuard`
closes such a connection (code 1008) from viser's connect callback, before any scene message is
sent; the handshake itself succeeds and the static page is served to anyone (docs/streaming.md,
Security). The viewer port has no token.

World: wearpose's Y-up frame (the viewer's up direction is set to +Y), metres. EM estimates
whose root is relative to the EM source (``extras["frame"] == "em_source"``) are placed in the
world with the recording's EM source pose offline when the recording has one
(:func:`run_recording_viewer`), and live as if the source were oriented as at rest
(:func:`source_rest_rotation`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import threading
import time
import warnings
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator, Sequence

import numpy as np
import torch
from websockets.datastructures import MultipleValuesError

from wearpose.body import PARENTS, BodyModel, forward_kinematics
from wearpose.errors import ShapeError
from wearpose.geometry import matrix_to_quat

if TYPE_CHECKING:
    from wearpose.estimators.base import Estimator
    from wearpose.estimators.run import ModelSource

from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR

VALID = np.array([40, 190, 80], np.uint8)
DROPPED = np.array([230, 40, 40], np.uint8)
BONES = [(j, p) for j, p in enumerate(PARENTS) if p >= 0]


def sensor_colours(valid: np.ndarray, interference: np.ndarray | None = None) -> np.ndarray:
    """``(S, 3)`` uint8: green valid / red dropped; with ``interference`` ``(S,)`` in [0, 1] valid
    sensors shade green -> orange -> red."""
    valid = np.asarray(valid, bool)
    col = np.where(valid[:, None], VALID, DROPPED).astype(np.float32)
    if interference is not None:
        x = np.clip(np.nan_to_num(np.asarray(interference, np.float32), nan=0.0), 0.0, 1.0)[:, None]
        warm = np.where(x < 0.5, VALID + (np.array([250, 160, 30]) - VALID) * (2 * x),
                        np.array([250, 160, 30]) + (DROPPED - np.array([250, 160, 30])) * (2 * x - 1))
        col = np.where(valid[:, None], warm, col)
    return col.astype(np.uint8)


def joint_colours(uncertainty: np.ndarray | None, scale: float | None = None) -> np.ndarray:
    """``(24, 3)`` uint8: white, or blue (certain) -> red (``uncertainty >= scale``)."""
    if uncertainty is None:
        return np.full((24, 3), 250, np.uint8)
    u = np.nan_to_num(np.asarray(uncertainty, np.float32), nan=0.0)
    s = float(scale) if scale else float(u.max() or 1.0)
    x = np.clip(u / s, 0, 1)[:, None]
    return (np.array([40, 90, 250]) * (1 - x) + np.array([240, 40, 40]) * x).astype(np.uint8)


class BodyLayer:
    """One body in a viser scene: skinned mesh, skeleton, joints and sensor sites.

    Why transforms: the browser applies the mesh's bone poses and scene-node poses as they
    arrive, but rebuilds a line or point geometry whose points change (a React re-render), so a
    skeleton drawn from new points every frame lagged the mesh under load. Here every joint is a
    frame node posed like its bone (global rotation, joint position); each bone is a fixed
    segment in its parent joint's frame (``J_j = J_p + R_p (J^rest_j - J^rest_p)``), each joint
    dot, sensor dot and the label hang from nodes that only move, so all of them change in the
    same kind of message as the mesh, in the same atomic batch.

    Args:
        server: a ``viser.ViserServer``.
        body: the body model whose mesh/skinning weights are drawn.
        name: scene node prefix and label.
        betas: ``(10,)`` shape of this body.
        colour: mesh colour (:mod:`wearpose.viewer.scene`).
        offset: ``(3,)`` m, display shift (side-by-side bodies).
        sites: body site names of the sensors drawn on this body (``()``: none).
    """

    def __init__(self, server: Any, body: BodyModel, name: str, betas: torch.Tensor, colour: tuple[int, int, int],
                 offset: Sequence[float] = (0.0, 0.0, 0.0), sites: Sequence[str] = (), opacity: float | None = None) -> None:
        self.server, self.body, self.name = server, body, name
        self.offset = np.asarray(offset, np.float32)
        with torch.no_grad():
            b = torch.as_tensor(betas, dtype=body.dtype).reshape(-1)[: body.num_betas]
            self.betas = b
            self.J_rest = body.rest_joints(b)
            v = body.v_template + torch.einsum("vcs,s->vc", body.shapedirs[..., : b.shape[0]], b)
        J = self.J_rest.cpu().numpy().astype(np.float32)
        self.sites = tuple(sites)
        self.mesh = server.scene.add_mesh_skinned(
            f"/{name}/mesh", v.cpu().numpy().astype(np.float32), body.faces.cpu().numpy().astype(np.uint32),
            bone_wxyzs=np.tile(np.array([1.0, 0, 0, 0], np.float32), (24, 1)), bone_positions=J,
            skin_weights=body.weights.cpu().numpy().astype(np.float32), color=colour, opacity=opacity,
            position=tuple(self.offset), cast_shadow=False, receive_shadow=False)  # shadows cost a pass per light
        self.frames = [server.scene.add_frame(f"/{name}/joint{j}", show_axes=False, position=tuple(J[j] + self.offset))
                       for j in range(24)]
        self.bone_lines = {j: server.scene.add_line_segments(  # bone j -> p, fixed in the parent's frame
            f"/{name}/joint{p}/bone{j}", np.stack([np.zeros(3, np.float32), J[j] - J[p]])[None],
            colors=(30, 30, 30), thickness=0.012) for j, p in BONES}
        self._joint_cols = joint_colours(None)
        self.joint_dots = [server.scene.add_point_cloud(f"/{name}/joint{j}/dot", np.zeros((1, 3), np.float32),
                                                        colors=self._joint_cols[j:j + 1], point_size=0.035,
                                                        point_shape="circle") for j in range(24)]
        self.sensor_frames, self.sensor_dots = [], []
        self._sensor_cols = np.zeros((0, 3), np.uint8)
        if self.sites:
            sp = body.sites(None, b, None, self.sites).positions.cpu().numpy().astype(np.float32)
            self._sensor_cols = sensor_colours(np.ones(len(sp), bool))
            for k, site in enumerate(self.sites):
                self.sensor_frames.append(server.scene.add_frame(f"/{name}/sensor{k}", show_axes=False,
                                                                 position=tuple(sp[k] + self.offset)))
                self.sensor_dots.append(server.scene.add_point_cloud(
                    f"/{name}/sensor{k}/dot", np.zeros((1, 3), np.float32), colors=self._sensor_cols[k:k + 1],
                    point_size=0.045, point_shape="circle"))
        self.label_anchor = server.scene.add_frame(f"/{name}/label_anchor", show_axes=False,
                                                   position=tuple(J[15] + self.offset + np.array([0, 0.35, 0], np.float32)))
        self.label = server.scene.add_label(f"/{name}/label_anchor/label", name)
        self.root = J[0] + self.offset  # (3,) m, world position of the root shown last

    @torch.no_grad()
    def show(self, local_rot: torch.Tensor, trans: torch.Tensor | None = None, sensor_valid: np.ndarray | None = None,
             interference: np.ndarray | None = None, uncertainty: np.ndarray | None = None,
             uncertainty_scale: float | None = None) -> None:
        """Pose the body: ``local_rot`` ``(24, 3, 3)``, ``trans`` ``(3,)`` m (None: zero)."""
        R = torch.as_tensor(local_rot, dtype=self.body.dtype)
        t = torch.zeros(3, dtype=self.body.dtype) if trans is None else torch.as_tensor(trans, dtype=self.body.dtype)
        G, J = forward_kinematics(R, self.J_rest)
        J = J + t
        q = matrix_to_quat(G).cpu().numpy()
        Jn = J.cpu().numpy().astype(np.float32)
        Jw = Jn + self.offset
        cols = joint_colours(uncertainty, uncertainty_scale)
        sp = sc = None
        if self.sites:
            sp = self.body.sites(R[None], self.betas, t[None], self.sites).positions[0].cpu().numpy().astype(np.float32)
            v = np.ones(len(self.sites), bool) if sensor_valid is None else np.asarray(sensor_valid, bool)
            sc = sensor_colours(v, interference)
        with self.server.atomic():
            for j in range(24):
                self.mesh.bones[j].wxyz = q[j]
                self.mesh.bones[j].position = Jn[j]
                self.frames[j].wxyz = q[j]
                self.frames[j].position = Jw[j]
                if not np.array_equal(cols[j], self._joint_cols[j]):  # a colour message only when it changes
                    self.joint_dots[j].colors = cols[j:j + 1]
            self._joint_cols = cols
            if sp is not None:
                for k, f in enumerate(self.sensor_frames):
                    f.position = sp[k] + self.offset
                    if not np.array_equal(sc[k], self._sensor_cols[k]):
                        self.sensor_dots[k].colors = sc[k:k + 1]
                self._sensor_cols = sc
            self.label_anchor.position = tuple(Jw[15] + np.array([0, 0.35, 0], np.float32))
        self.root = Jw[0]


#: Seconds the viewer waits for its WebSocket to close cleanly before it exits anyway.
CLOSE_TIMEOUT_S = 2.0

log = logging.getLogger("wearpose.viewer")


class OriginGuard:
    """Closes viser connections whose ``Origin`` is not allowed (viser has no option for it).

    Allowed: no ``Origin`` header (a non-browser client), this machine's pages on the viewer's
    port (``http://127.0.0.1:P``, ``http://localhost:P``, ``http://[::1]:P``) and
    ``allow_origins``. A refused connection is closed with code 1008 in viser's connect callback,
    which runs before any scene message is sent; :attr:`refused` counts them.

    It reads viser's table of live connections (``ViserServer._websock_server._live_connections``,
    viser 1.1): where that is missing, :attr:`active` is False and a warning says the viewer
    port is unchecked.
    """

    def __init__(self, server: Any, allow_origins: Sequence[str] = ()) -> None:
        # start-up: wearpose.stream.security adds ~100 ms to import wearpose.viewer
        from wearpose.stream.security import normalise_origin, same_host_origins

        self.allowed = {None, *same_host_origins([server.get_port()]), *(normalise_origin(o) for o in allow_origins)}
        self.refused = 0
        self.active = self._install(server)

    def _install(self, server: Any) -> bool:
        infra = getattr(server, "_websock_server", None)
        conns = getattr(infra, "_live_connections", None)
        if not isinstance(conns, dict) or not callable(getattr(infra, "on_client_connect", None)):
            warnings.warn("this viser version offers no way to check the Origin of viewer connections: any web "
                          "page in this machine's browser can read the viewer's scene (docs/streaming.md, Security)")
            return False

        async def check(client: Any) -> None:
            ws = conns.get(client.client_id)
            if ws is None or self.allows(ws.request):
                return
            self.refused += 1
            log.warning("viewer: refused a connection from Origin %r (#%d)", _origin(ws.request), self.refused)
            await ws.close(1008, "Origin not allowed")

        infra.on_client_connect(check)
        return True

    def allows(self, request: Any) -> bool:
        """Whether a handshake ``request`` (``websockets.http11.Request``) comes from an allowed page."""
        try:
            return _origin(request) in self.allowed
        except ValueError:  # several Origin headers
            return False


def _origin(request: Any) -> str | None:
    try:
        return None if request is None else request.headers.get("Origin")
    except MultipleValuesError:
        raise ValueError("several Origin headers") from None


def _warn_if_exposed(host: str, port: int) -> None:
    # start-up: wearpose.stream.security adds ~100 ms to import wearpose.viewer
    from wearpose.stream.security import is_loopback_host

    if not is_loopback_host(host):
        warnings.warn(f"the viewer listens on {host}:{port}, beyond this machine, and its port has no access token "
                      f"(viser offers no hook for one): any program that can reach it sees the poses, and browsers on "
                      f"other machines need --allow-origin http://NAME:{port}; prefer 127.0.0.1 and an SSH tunnel")


def _new_server(host: str, port: int, allow_origins: Sequence[str] = ()) -> Any:
    import viser  # start-up: viser adds ~250 ms to import wearpose.viewer

    server = viser.ViserServer(host=host, port=port, verbose=False)
    server.origin_guard = OriginGuard(server, allow_origins)  # before any page can connect to a scene
    server.scene.set_up_direction("+y")
    server.scene.configure_default_lights(True, cast_shadow=False)
    server.scene.configure_environment_map(None)  # the default HDRI washes the colours out
    server.gui.configure_theme(control_width="small", show_share_button=False)
    _frame_scene(server, np.zeros(3, np.float32), -1.15)
    return server


def _frame_scene(server: Any, centre: np.ndarray, ground_y: float, distance: float = 6.0) -> None:
    """Ground grid at ``ground_y`` m (endless: a walking body never leaves it); camera
    ``distance`` m in front (+Z) of ``centre`` (bodies sit at ``centre + (0, 1, 2 ...) m`` along
    X, facing +Z)."""
    c = np.asarray(centre, np.float32)
    server.scene.add_grid("/ground", plane="xz", position=(float(c[0]), float(ground_y), float(c[2])),
                          infinite_grid=True, fade_distance=30.0)
    server.initial_camera.position = (float(c[0]) + 0.5, float(c[1]) + 0.6, float(c[2]) + distance)
    server.initial_camera.look_at = (float(c[0]) + 0.5, float(c[1]) - 0.3, float(c[2]))


class CameraFollow:
    """Keeps every browser's camera on a moving body: its look-at point is the initial camera's,
    moved over the floor (X, Z) as far as the body's root has moved; the user's orbit (camera
    minus look-at: direction and distance) is kept, so only panning is taken over.

    Why absolute and gated: the server's copy of a client's camera is overwritten by the
    client's reports, which lag what the server sent; adding each frame's root motion to that
    copy lost the motion of every report in flight (the camera fell behind the body), and the
    first report can be viser's default camera ((3, 3, 3) looking at the origin) sent before the
    page applied ``initial_camera``: moving that one replaced the initial view with a high
    oblique one. Here the look-at is computed from the root alone (a stale report only delays a
    frame), and a client is followed once it has reported the initial camera (position and
    look-at in one report: the page applies them one at a time, and a torn first report, the
    initial look-at seen from viser's default position, kept the oblique orbit).

    Args:
        server: the ``viser.ViserServer``.
        root0: ``(3,)`` m, world position of the followed root when the initial camera was set.
    """

    def __init__(self, server: Any, root0: np.ndarray) -> None:
        self.server = server
        self.look0 = np.asarray(server.initial_camera.look_at, np.float64)
        self.pos0 = np.asarray(server.initial_camera.position, np.float64)
        self.root0 = np.asarray(root0, np.float64)
        self.orbit: dict[int, np.ndarray] = {}  # client id -> camera minus look-at, m (clients shown the initial camera)
        self.sent: dict[int, deque] = {}  # client id -> the last (position, look-at) pairs sent to it
        self._lock = threading.Lock()

    def target(self, root: np.ndarray) -> np.ndarray:
        """``(3,)`` m, the look-at point for a root at ``root`` ``(3,)`` m (height unchanged)."""
        d = np.asarray(root, np.float64) - self.root0
        return self.look0 + np.array([d[0], 0.0, d[2]])

    def follow(self, root: np.ndarray) -> None:
        """Move every ready client's camera to look at :meth:`target` from its orbit."""
        look = self.target(root)
        with self._lock:  # the player thread and GUI callbacks both draw frames
            clients = self.server.get_clients()
            for gone in set(self.orbit) - set(clients):  # disconnected: new connections get new ids
                self.orbit.pop(gone)
                self.sent.pop(gone, None)
            for cid, client in clients.items():
                # One report: viser replaces a client's camera state object on each report, so
                # reading position and look_at through the handle could mix two reports.
                state = getattr(client.camera, "_state", None) or client.camera
                pos, at = np.array(state.position, np.float64), np.array(state.look_at, np.float64)
                orbit = self._orbit(cid, pos, at)
                if orbit is None:
                    continue  # the page has not applied initial_camera yet: its report is viser's default
                with client.atomic():  # both in one batch
                    client.camera.position = look + orbit  # viser moves look_at by the same offset
                    client.camera.look_at = look
                self.sent.setdefault(cid, deque(maxlen=64)).append((look + orbit, look))

    def _orbit(self, cid: int, pos: np.ndarray, at: np.ndarray) -> np.ndarray | None:
        """The orbit ``(3,)`` m to keep for client ``cid`` given its last report (``pos``, ``at``
        ``(3,)`` m); None before the page has shown the initial camera.

        The page applies a camera's position and look-at one after the other and may report in
        between, so a report can be torn: one half of a pair we sent with the other half of
        another. Both halves are gated: a first report of the initial look-at seen from viser's
        default position (3, 3, 3) kept that oblique orbit for good, and a torn report during
        the follow shifted the orbit by a frame's motion each time (the camera fell behind the
        walking body). So the orbit is kept per client and replaced only by a report that is not
        two halves of what was sent: the user's own orbiting (look-at as sent, a new position)."""
        if cid not in self.orbit:
            if not (np.allclose(at, self.look0, atol=1e-3) and np.allclose(pos, self.pos0, atol=1e-3)):
                return None
        elif np.allclose(pos - at, self.orbit[cid], atol=1e-3) or self._torn(cid, pos, at):
            return self.orbit[cid]
        self.orbit[cid] = pos - at
        return self.orbit[cid]

    def _torn(self, cid: int, pos: np.ndarray, at: np.ndarray) -> bool:
        """Whether ``pos`` is a position and ``at`` a look-at sent to client ``cid`` (within 1 mm;
        one vectorised test over the kept pairs: this runs on the drawing path while a user orbits)."""
        sent = self.sent.get(cid)
        if not sent:
            return False
        pairs = np.asarray(sent)  # (n, 2, 3): position, look-at
        near = lambda x, rows: bool(np.isclose(x, rows, atol=1e-3).all(-1).any())  # noqa: E731
        return near(pos, pairs[:, 0]) and near(at, pairs[:, 1])


def _kit_sites(kit: str | None, sensor_names: Sequence[str], body: BodyModel) -> tuple[tuple[str, ...], str | None]:
    """Body sites of ``sensor_names`` of ``kit`` on ``body`` and the kit's EM source site
    (``((), None)`` if the kit is unknown)."""
    # start-up: wearpose.sensors adds ~90 ms to import wearpose.viewer
    from wearpose.sensors import get_kit, resolve_sites

    try:
        k = get_kit(kit) if kit else None
        if k is None:
            return (), None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sites, _ = resolve_sites(k, body.site_names, body.asset_id)
        return tuple(sites[n] for n in sensor_names), sites.get("<em_source>")
    except Exception:  # noqa: BLE001 - an unknown kit or site just means no sensor dots
        return (), None


def source_rest_rotation(body: BodyModel, betas: torch.Tensor, source_site: str) -> torch.Tensor:
    """``(3, 3)`` world orientation of the EM source site in the rest pose.

    Live EM estimates give the root relative to the EM source; the live viewer shows them as if
    the source were oriented as at rest (``R_root_world = R_site_rest @ R_root_source``), so an
    upright subject stands upright; the source's real heading and position are unknown live.
    """
    with torch.no_grad():
        return body.sites(None, torch.as_tensor(betas, dtype=body.dtype), None, [source_site]).rotations[0]


class _Timeline:
    """GUI: frame slider, play/pause, speed, and a text panel."""

    def __init__(self, server: Any, num_frames: int, fps: float, title: str, live: bool = False) -> None:
        self.server, self.fps = server, fps
        server.gui.add_markdown(f"**{title}**")
        self.follow = server.gui.add_checkbox("follow live", True) if live else None
        # Offline: the camera moves with the first body over the floor, keeping the user's orbit
        # around it (CameraFollow); untick it to pan freely.
        self.camera_follows = None if live else server.gui.add_checkbox("camera follows", True)
        self.slider = server.gui.add_slider("frame", min=0, max=max(1, num_frames - 1), step=1, initial_value=0)
        self.playing = server.gui.add_checkbox("play", not live)
        self.speed = server.gui.add_slider("speed", min=0.1, max=4.0, step=0.1, initial_value=1.0)
        self.info = server.gui.add_markdown("")


def _sensor_grid(recording: Any, names: Sequence[str] | None) -> Any:
    """``names``' (None: all) samples on one time grid, for the sensor dots' valid colours: the
    recording's own when the sensors share one, else the nearest-sample grid the segment
    estimator puts devices with their own clocks on (x-IMU3; nothing interpolated, a lost
    sample stays masked)."""
    from wearpose.recording import RecordingError  # start-up: wearpose.recording adds ~50 ms to import wearpose.viewer

    try:
        return recording.on_common_grid(names)
    except RecordingError:
        # start-up: wearpose.estimators.inputs adds ~150 ms to import wearpose.viewer
        from wearpose.estimators.inputs import nearest_sample_grid

        return nearest_sample_grid(recording, tuple(names or recording.names)).on_common_grid()


class RecordingViewer:
    """Offline viewer of a recording and/or an estimate (module doc).

    Args:
        recording: a :class:`~wearpose.recording.Recording` (its ``ground_truth`` is shown when
            present; its sensors' validity colours the sensor dots) or None.
        track: an estimated :class:`~wearpose.estimators.PoseTrack` or None; its extras
            ``interference`` ``(T, S)`` and ``uncertainty`` ``(T, 24)`` colour sensors / joints.
        sensor_names: the track's sensors (default: the recording's), for the sensor dots.
        body: body model (default: the embedded asset).
        autoplay: start playing.
        camera_distance: m, initial camera distance in front of the first frame's root.
        allow_origins: browser origins allowed besides this machine's pages (:class:`OriginGuard`).
    """

    def __init__(self, recording: Any = None, track: Any = None, *, sensor_names: Sequence[str] | None = None,
                 body: BodyModel | None = None, host: str = "127.0.0.1", port: int = 8080, title: str = "wearpose",
                 autoplay: bool = True, camera_distance: float = 6.0, allow_origins: Sequence[str] = ()) -> None:
        gt = getattr(recording, "ground_truth", None)
        if track is None and gt is None:
            raise ShapeError("RecordingViewer: nothing to show (no estimate and the recording has no ground truth)")
        self.body = body or BodyModel()
        self.track, self.gt = track, gt
        self.gt_start = float(getattr(recording, "ground_truth_start", 0.0))
        self.fps = float(track.fps if track is not None else gt.fps)
        self.num_frames = int(track.num_frames if track is not None else gt.num_frames)
        self.grid = _sensor_grid(recording, sensor_names) if recording is not None and recording.names else None
        names = tuple(self.grid.names) if self.grid is not None else ()
        infos = [recording.sensor(n).info for n in names]
        keep = [i for i, inf in enumerate(infos) if inf.site in self.body.site_names]
        self.sensor_idx = keep
        sites = tuple(infos[i].site for i in keep)
        self.server = _new_server(host, port, allow_origins)
        self.port = self.server.get_port()
        self.layers: dict[str, BodyLayer] = {}
        if track is not None:
            self.layers["estimate"] = BodyLayer(self.server, self.body, "estimate", track.betas, ESTIMATE_COLOUR, sites=sites)
        if gt is not None:
            self.layers["ground truth"] = BodyLayer(self.server, self.body, "ground truth", gt.betas, TRUTH_COLOUR,
                                                    offset=(1.0 if track is not None else 0.0, 0, 0),
                                                    sites=() if track is not None else sites)
        unc = getattr(track, "uncertainty", None) if track is not None else None
        self.unc_scale = float(torch.nan_to_num(unc).max()) if unc is not None else None
        first = track if track is not None and track.trans is not None else None
        with torch.no_grad():
            if first is not None:
                _, J0 = forward_kinematics(first.local_rot[0].to(self.body.dtype), self.body.rest_joints(first.betas.to(self.body.dtype)))
                J0 = J0 + first.trans[0].to(self.body.dtype)
            elif gt is not None:
                _, J0 = forward_kinematics(gt.pose[0].to(self.body.dtype), self.body.rest_joints(gt.betas.to(self.body.dtype)))
                J0 = J0 + gt.trans[0].to(self.body.dtype)
            else:
                _, J0 = forward_kinematics(track.local_rot[0].to(self.body.dtype), self.body.rest_joints(track.betas.to(self.body.dtype)))
        J0 = J0.cpu().numpy()
        _frame_scene(self.server, J0[0], float(J0[:, 1].min()) - 0.08, camera_distance)
        self.timeline = _Timeline(self.server, self.num_frames, self.fps, title)
        self.timeline.playing.value = autoplay
        self.timeline.slider.on_update(self._on_slider)
        self._stop = threading.Event()
        # The camera follows the body that moves over the floor: the estimate when it has a root
        # translation, else the ground truth.
        self.lead = "estimate" if first is not None or gt is None else "ground truth"
        self.show(0)
        self.camera = CameraFollow(self.server, self.layers[self.lead].root)
        self.timeline.camera_follows.on_update(lambda _: self._follow_camera())
        self._player = threading.Thread(target=self._play, daemon=True, name="wearpose-viewer-play")
        self._player.start()

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.port}"

    def _on_slider(self, event: Any) -> None:
        if event.client is not None:  # a user dragged it (the player draws its own frames)
            self.show(int(self.timeline.slider.value))

    def show(self, i: int) -> None:
        """Draw frame ``i`` of the timeline."""
        i = int(np.clip(i, 0, self.num_frames - 1))
        t = i / self.fps
        valid = interference = None
        if self.grid is not None:
            g = int(np.clip(np.searchsorted(self.grid.timestamps, self.grid.timestamps[0] + t - 1e-6), 0,
                            len(self.grid.timestamps) - 1))
            valid = self.grid.valid[g][self.sensor_idx]
        text = [f"t = {t:6.2f} s (frame {i} / {self.num_frames - 1})"]
        if self.track is not None:
            tr = self.track
            inter = tr.extras.get("interference")
            if inter is not None:
                interference = np.asarray(inter[i])[self.sensor_idx]
            self.layers["estimate"].show(tr.local_rot[i], None if tr.trans is None else tr.trans[i], valid, interference,
                                         None if tr.uncertainty is None else tr.uncertainty[i].numpy(), self.unc_scale)
            text.append(f"estimate: {'valid' if bool(tr.valid[i]) else 'INVALID (masked input)'}, "
                        f"frame {tr.extras.get('frame', 'world')}")
        if self.gt is not None:
            k = int(np.clip(round((t - self.gt_start) * self.gt.fps), 0, self.gt.num_frames - 1))
            self.layers["ground truth"].show(self.gt.pose[k], self.gt.trans[k], valid if self.track is None else None)
        if valid is not None:
            text.append(f"sensors valid: {int(valid.sum())} / {len(valid)}")
        self.timeline.info.content = "  \n".join(text)
        self._follow_camera()

    def _follow_camera(self) -> None:
        """Point every client's camera at the first body when "camera follows" is ticked."""
        camera = getattr(self, "camera", None)  # None while the first frame is drawn
        if camera is not None and self.timeline.camera_follows.value:
            camera.follow(self.layers[self.lead].root)

    def _play(self) -> None:
        last = time.perf_counter()
        pos = float(self.timeline.slider.value)
        while not self._stop.is_set():
            time.sleep(1 / 30)
            now = time.perf_counter()
            if self.timeline.playing.value:
                if int(pos) != int(self.timeline.slider.value):  # the user moved the slider
                    pos = float(self.timeline.slider.value)
                pos = (pos + (now - last) * self.fps * float(self.timeline.speed.value)) % self.num_frames
                if int(pos) != int(self.timeline.slider.value):
                    self.timeline.slider.value = int(pos)
                    self.show(int(pos))
            last = now

    def close(self) -> None:
        self._stop.set()
        self._player.join(2)
        self.server.stop()


class LiveViewer:
    """Live viewer of a streaming server's poses (module doc).

    Args:
        url: ``ws://host:port`` of the server.
        subjects: subject ids to show (None: all).
        history_s: seconds of poses kept for the timeline.
        token: the streaming server's access token (when it requires one).
        allow_origins: browser origins allowed on the viewer's port besides this machine's pages.
    """

    def __init__(self, url: str, *, subjects: list[int] | None = None, body: BodyModel | None = None,
                 host: str = "127.0.0.1", port: int = 8080, history_s: float = 30.0, token: str | None = None,
                 allow_origins: Sequence[str] = ()) -> None:
        self.url_server = url
        self.token = token
        self.subjects = subjects
        self.body = body or BodyModel()
        self.history_s = history_s
        self.dropped_by_server = 0  # poses the server dropped because this viewer read too slowly
        self.server = _new_server(host, port, allow_origins)
        self.port = self.server.get_port()
        self.history: dict[int, deque] = {}
        self.meta: dict[int, dict[str, Any]] = {}
        self.layers: dict[int, BodyLayer] = {}
        self.source_rest: dict[int, torch.Tensor] = {}
        self.received = 0
        self.shown = 0
        self.timeline = _Timeline(self.server, 2, 30.0, f"live: {url}", live=True)
        self._lock = threading.Lock()

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.port}"

    def _on_pose(self, t: float, p: Any) -> None:
        with self._lock:
            h = self.history.get(p.subject)
            if h is None:
                rate = float(self.meta.get(p.subject, {}).get("rate") or 120.0)
                h = self.history[p.subject] = deque(maxlen=max(2, int(self.history_s * rate)))
            h.append(p)
            self.received += 1

    def _layer(self, k: int, p: Any) -> BodyLayer:
        if k not in self.layers:
            m = self.meta.get(k, {})
            names = m.get("estimator_sensors") or []
            sites, src = _kit_sites(m.get("kit"), names, self.body)
            if src is not None:
                self.source_rest[k] = source_rest_rotation(self.body, torch.as_tensor(p.betas), src)
            self.layers[k] = BodyLayer(self.server, self.body, f"subject {k}", torch.as_tensor(p.betas), ESTIMATE_COLOUR,
                                       offset=(1.2 * len(self.layers), 0, 0), sites=sites)
        return self.layers[k]

    def render(self) -> None:
        """Draw each subject's pose: the latest, or the one at the timeline when not following."""
        with self._lock:
            hist = {k: list(h) for k, h in self.history.items()}
        if not hist:
            return
        follow = bool(self.timeline.follow.value)
        n = max(len(h) for h in hist.values())
        self.timeline.slider.max = max(1, n - 1)
        if follow:
            self.timeline.slider.value = n - 1
        i = int(self.timeline.slider.value)
        lines = []
        for k, h in sorted(hist.items()):
            p = h[min(i, len(h) - 1)] if not follow else h[-1]
            layer = self._layer(k, p)
            inter = p.extras.get("interference")
            valid = p.extras.get("sensor_valid")
            rot = torch.as_tensor(p.local_rot, dtype=self.body.dtype).clone()
            if p.extras.get("frame") == "em_source" and k in self.source_rest:
                rot[0] = self.source_rest[k] @ rot[0]  # see source_rest_rotation
            layer.show(rot, None if p.trans is None else torch.as_tensor(p.trans),
                       None if valid is None or len(valid) != len(layer.sites) else np.asarray(valid, bool),
                       None if inter is None or len(inter) != len(layer.sites) else np.asarray(inter, np.float32),
                       p.uncertainty)
            lines.append(f"subject {k}: t = {p.timestamp:.2f} s, seq {p.seq}, {'valid' if p.valid else 'INVALID'}, "
                         f"estimator {p.compute_ms:.1f} ms, server {p.server_ms:.1f} ms")
        self.shown += 1
        dropped = f", dropped by the server (viewer too slow): {self.dropped_by_server}" if self.dropped_by_server else ""
        self.timeline.info.content = "  \n".join(lines + [f"poses received: {self.received}{dropped}"])

    async def run(self, stop: asyncio.Event | None = None, fps: float = 30.0, *, handle_signals: bool = False,
                  on_subscribed: Callable[[], None] | None = None) -> str:
        """Subscribe and render at ``fps`` until ``stop`` is set, the server closes the
        connection, or (``handle_signals``) SIGINT/SIGTERM arrive. ``on_subscribed`` is called
        once the subscription is sent.

        Returns:
            why it stopped: ``"stopped"`` (``stop`` set or a signal) or ``"upstream closed"``.
        """
        # start-up: wearpose.stream.client adds ~120 ms to import wearpose.viewer
        from wearpose.stream.client import StreamClient

        stop = stop or asyncio.Event()
        loop = asyncio.get_running_loop()
        signals = (signal.SIGINT, signal.SIGTERM) if handle_signals else ()
        previous_term = signal.getsignal(signal.SIGTERM)
        for sig in signals:
            # Why our own handlers: asyncio.run's SIGINT handling cancels the main task, and a
            # cancellation arriving inside wait_for/close on a dead connection could be lost
            # (view-live ignored Ctrl-C after its server stopped); a flag the loop polls cannot be.
            loop.add_signal_handler(sig, stop.set)
        client = StreamClient(self.url_server, on_pose=self._on_pose, token=self.token)
        why = "stopped"
        try:
            await client.connect()
            await client.subscribe(self.subjects, "json")
            if on_subscribed is not None:
                on_subscribed()
            while not stop.is_set():
                for m in list(client.messages):
                    if m.get("type") == "subject":
                        self.meta[int(m["subject"])] = m
                self.dropped_by_server = client.dropped_poses
                self.render()
                if client.disconnected:  # the server stopped: nothing more will come
                    why = "upstream closed"
                    break
                await asyncio.sleep(1.0 / fps)
        finally:
            try:
                await asyncio.wait_for(client.close(), CLOSE_TIMEOUT_S)
            except (asyncio.TimeoutError, OSError):
                pass  # a half-dead connection must not keep the process alive
            for sig in signals:
                loop.remove_signal_handler(sig)
                if sig == signal.SIGTERM:  # remove_signal_handler leaves SIG_DFL: keep SIGTERM a clean stop
                    signal.signal(sig, previous_term)
        return why

    def close(self) -> None:
        self.server.stop()


def _terminate(signum: int, frame: Any) -> None:
    """SIGTERM (``kill``, a service manager) as Ctrl-C: the viewers' same clean stop."""
    raise KeyboardInterrupt


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Inside: SIGTERM raises KeyboardInterrupt (:func:`_terminate`); on leaving, the handler that
    was there before is back, so a program that calls a blocking viewer keeps its own. Main
    thread only (Python's signal rule)."""
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def run_live_viewer(url: str, *, host: str = "127.0.0.1", port: int = 8080, subjects: list[int] | None = None,
                    body: str | None = None, token: str | None = None, allow_origins: Sequence[str] = ()) -> str:
    """Blocking: the live viewer (``wearpose view-live``) until Ctrl-C / SIGTERM, or until the
    server closes the connection (it says so and returns). Returns why it stopped."""
    _warn_if_exposed(host, port)
    v = LiveViewer(url, subjects=subjects, body=BodyModel(body), host=host, port=port, token=token,
                   allow_origins=allow_origins)
    why = "stopped"
    try:
        with sigterm_as_interrupt():
            print(f"viewer on {v.url} (poses from {url}); Ctrl-C to stop", flush=True)
            why = asyncio.run(v.run(handle_signals=True,
                                    on_subscribed=lambda: print(f"subscribed to {url}", flush=True)))
    except KeyboardInterrupt:
        pass
    finally:
        v.close()
    if why == "upstream closed":
        print(f"the server at {url} closed the connection; viewer stopped ({v.received} poses received)", flush=True)
    return why


def open_recording_viewer(path: str | Path, *, model: ModelSource | None = None, host: str = "127.0.0.1",
                          port: int = 8080, body: str | None = None, allow_origins: Sequence[str] = (),
                          resample: bool | None = None, estimator: Estimator | None = None) -> RecordingViewer:
    """The offline viewer of a recording file (and ``model``'s estimate, made as ``wearpose
    estimate`` makes it: :func:`wearpose.estimators.run.estimate_recording`; ``estimator``, one
    made by ``model.make()`` with its settings changed, is used instead of a fresh one), serving
    until :meth:`RecordingViewer.close`."""
    from wearpose.recording import load_recording  # start-up: wearpose.recording adds ~50 ms to import wearpose.viewer

    rec = load_recording(path)
    track, names = None, None
    bm = BodyModel(body)
    if model is not None:
        # start-up: wearpose.estimators.run adds ~70 ms to import wearpose.viewer
        from wearpose.estimators.run import estimate_recording

        run = estimate_recording(model, rec, path, resample=resample, estimator=estimator)
        if run.note:
            print(f"warning: {run.note}", flush=True)
        rec, track, bm = run.recording, run.track, run.body
        # an estimator for any kit (segments) names no sensors: the ones its estimate used
        names = run.estimator.sensor_names or tuple(track.extras.get("segments", {})) or None
    _warn_if_exposed(host, port)
    return RecordingViewer(rec, track, sensor_names=names, body=bm, host=host, port=port,
                           title=f"wearpose: {Path(path).name}", allow_origins=allow_origins)


def run_recording_viewer(path: str | Path, *, model: ModelSource | None = None, host: str = "127.0.0.1",
                         port: int = 8080, body: str | None = None, allow_origins: Sequence[str] = (),
                         resample: bool | None = None, estimator: Estimator | None = None) -> None:
    """Blocking: :func:`open_recording_viewer` (``wearpose view-recording``) until Ctrl-C / SIGTERM."""
    v = open_recording_viewer(path, model=model, host=host, port=port, body=body, allow_origins=allow_origins,
                              resample=resample, estimator=estimator)
    print(f"viewer on {v.url}; Ctrl-C to stop", flush=True)
    try:
        with sigterm_as_interrupt():
            while True:
                time.sleep(1)
    except KeyboardInterrupt:
        pass
    finally:
        v.close()
