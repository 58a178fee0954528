"""Hip, knee and ankle angles of ``--model segments`` beside x-io's own solver (``imumocap``).

The real x-IMU3 lower-body log (``../shared/real-sensors/ximu3-lower-body``) through both solvers,
joint angles in imumocap's own definition, RMS difference per joint and axis. Two parts, two
interpreters (imumocap 1.4.0 needs Python >= 3.12; wearpose runs on 3.11, so imumocap is not a
dependency of wearpose):

1. ``reference`` -- run with a Python 3.12 venv holding ``imumocap==1.4.0 ximu3csv==1.0.5``
   (numpy, scipy, matplotlib beside them); imports neither torch nor wearpose. It is x-io's
   ``Examples/logged_lower_body.py`` (IMU-Mocap, the same log) without the plot: read the
   quaternions, resample to ``--fps`` (slerp), the lower-body model of ``Examples/models.py``,
   ``calibrate(model, frame 0, mounting=Z_BACKWARD)``, ``set_pose_from_imus`` per frame. It
   writes, per frame and joint, the joint's rotation matrix (child link relative to parent link,
   imumocap link axes: x forward, y left, z up), the joint's ``alignment`` and its angles
   ``Joint.get()`` (``alpha, beta, gamma``: ZYX Euler angles of ``A^T R A``, degrees)::

       /work/venv312/bin/python benchmarks/imumocap_compare.py reference --out /tmp/imumocap_angles.json

2. ``compare`` -- run with wearpose's venv: imports the log (``wearpose.recording.from_ximu3``,
   as ``wearpose recording import ximu3``), runs the segment estimator (as ``wearpose estimate
   --model segments``), re-expresses its local joint rotations in imumocap's link axes
   (``SMPL_TO_X_FORWARD_BODY``) and decomposes them with imumocap's alignments and Euler order,
   then compares at the same instants (nearest wearpose grid frame to each imumocap timestamp,
   within half a grid period; invalid wearpose frames skipped)::

       .venv/bin/python benchmarks/imumocap_compare.py compare --reference /tmp/imumocap_angles.json

Alignments (each stated, none fitted to the reference):

- ``as shipped``: each solver with its own calibration (wearpose: chordal mean over the first
  0.5 s, tilt from the accelerometers, heading from the skin normals; imumocap: the AHRS frame
  as is, heading from the pelvis sensor's -z axis, frame 0 only).
- ``same calibration instant``: wearpose calibrated on a 0.1 s window starting at imumocap's
  frame 0 (the shortest window the estimator takes).
- ``same instant + same body axes``: as above, and wearpose's joint rotations re-expressed in
  the body axes imumocap calibrated (``D = R_z(h)^T C^T S^T``, C: wearpose's world alignment
  ``R^{WM}`` composed with the Z-up -> Y-up change, h: imumocap's heading, S:
  ``SMPL_TO_X_FORWARD_BODY``); a constant rotation computed from the two calibrations, whose
  angle is reported.

Diagnostics of the residual (one more aligned row each, ``compare --also FILE...``):

- ``reference --order tree``: imumocap with the IMUs applied parents first. ``Model.set_pose_from_imus``
  sets each link's joint from its IMU against its parent's pose *at that moment*; x-io's example
  passes the devices in folder order (``Path.iterdir``, filesystem-dependent; here Right Foot,
  Right Upper Leg, Left Upper Leg, Pelvis, ...), so a child applied before its parent is solved
  against the parent's previous frame.
- ``samples`` then ``reference --samples FILE``: imumocap on the very rows wearpose's grid used
  (nearest sample per device, no slerp), at wearpose's grid instants.

Full run (the results file)::

    /work/venv312/bin/python benchmarks/imumocap_compare.py reference --out /tmp/imumocap_angles.json
    /work/venv312/bin/python benchmarks/imumocap_compare.py reference --order tree --out /tmp/imumocap_tree.json
    .venv/bin/python benchmarks/imumocap_compare.py samples --out /tmp/wearpose_samples.json
    /work/venv312/bin/python benchmarks/imumocap_compare.py reference --samples /tmp/wearpose_samples.json \
        --out /tmp/imumocap_file_same.json
    /work/venv312/bin/python benchmarks/imumocap_compare.py reference --order tree --samples /tmp/wearpose_samples.json \
        --out /tmp/imumocap_tree_same.json
    .venv/bin/python benchmarks/imumocap_compare.py compare --also /tmp/imumocap_tree.json \
        /tmp/imumocap_file_same.json /tmp/imumocap_tree_same.json

Writes ``benchmarks/results/imumocap_compare.{md,json}``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Sequence

HERE = Path(__file__).resolve().parent
LOG = HERE.parents[1] / "shared" / "real-sensors" / "ximu3-lower-body"
#: imumocap joint -> (its link, the SMPL joint whose local rotation is the same relative rotation).
JOINTS = {"Left Hip": ("Left Upper Leg", "left_hip"), "Right Hip": ("Right Upper Leg", "right_hip"),
          "Left Knee": ("Left Lower Leg", "left_knee"), "Right Knee": ("Right Lower Leg", "right_knee"),
          "Left Ankle": ("Left Foot", "left_ankle"), "Right Ankle": ("Right Foot", "right_ankle")}
AXES = ("alpha", "beta", "gamma")
#: Reference joint angular speed (deg/s) below which a frame counts as slow in the residual split.
SLOW_DEG_S = 30.0


# ----------------------------------------------------------------------------- part 1 (Python 3.12)
def lower_body_model() -> Any:
    """imumocap's lower-body model: ``Examples/models.py`` (IMU-Mocap, MIT), its legs and pelvis.

    Link lengths do not enter joint angles; the joints' alignments are x-io's.
    """
    from imumocap import Joint, Link, Matrix, Model

    lf_toe, rf_toe = Link("Left Toe", Matrix(x=0.05)), Link("Right Toe", Matrix(x=0.05))
    lf = Link("Left Foot", Matrix(z=-0.10)).connect(lf_toe, Matrix(x=0.15))
    rf = Link("Right Foot", Matrix(z=-0.10)).connect(rf_toe, Matrix(x=0.15))
    ll = Link("Left Lower Leg", Matrix(z=-0.45)).connect(lf)
    rl = Link("Right Lower Leg", Matrix(z=-0.45)).connect(rf)
    lu = Link("Left Upper Leg", Matrix(z=-0.45)).connect(ll)
    ru = Link("Right Upper Leg", Matrix(z=-0.45)).connect(rl)
    pelvis = Link("Pelvis", Matrix(z=0.15))
    pelvis.connect(lu, Matrix(y=0.15, z=-0.15))
    pelvis.connect(ru, Matrix(y=-0.15, z=-0.15))
    joints = {
        "Left Toe": Joint(lf_toe, Matrix.align_px_nz_py()), "Left Ankle": Joint(lf, Matrix.align_nz_px_ny()),
        "Left Knee": Joint(ll, Matrix.align_nz_nx_py()), "Left Hip": Joint(lu, Matrix.align_nz_px_ny()),
        "Right Toe": Joint(rf_toe, Matrix.align_nx_pz_py()), "Right Ankle": Joint(rf, Matrix.align_pz_nx_ny()),
        "Right Knee": Joint(rl, Matrix.align_pz_px_py()), "Right Hip": Joint(ru, Matrix.align_pz_nx_ny()),
        "Pelvis": Joint(pelvis, Matrix.align_py_nx_pz()),
    }
    return Model(pelvis, joints)


def reference(log: Path, fps: float, out: Path, samples: Path | None = None, order: str = "file") -> None:
    """Part 1: imumocap's solution of the log (module doc), written to ``out`` (JSON). With
    ``samples`` (from part ``samples``): imumocap on the very rows wearpose's grid used, no
    resampling (the diagnostic of the residual). ``order``: the order the IMUs are applied in each
    frame, ``file`` (x-io's example: the device folders as ``ximu3csv.read`` lists them) or
    ``tree`` (the model's links, parents first; module doc)."""
    import imumocap
    import imumocap.solvers
    import numpy as np
    import ximu3csv
    from imumocap import Matrix
    from imumocap.solvers import Mounting

    raw = ximu3csv.read(log, ximu3csv.DataMessageType.QUATERNION)
    first_us = min(int(d.quaternion.timestamp[0]) for d in raw)
    if samples is None:  # x-io's example: slerp-resampled to fps on one grid
        devices = ximu3csv.resample(raw, fps)
        stamps = [float(t) for t in devices[0].quaternion.timestamp]
        frames = [{d.device_name: Matrix(quaternion=d.quaternion.quaternion.wxyz[i]) for d in devices}
                  for i in range(len(stamps))]
    else:  # the raw rows wearpose's grid used (part "samples"), instants where every device has one
        want = json.loads(samples.read_text())
        rows = {d.device_name: {int(t): i for i, t in enumerate(d.quaternion.timestamp)} for d in raw}
        q = {d.device_name: d.quaternion.quaternion.wxyz for d in raw}
        stamps, frames = [], []
        for k, t in enumerate(want["timestamps_us"]):
            use = {n: want["devices"][n][k] for n in rows}
            if all(u is not None for u in use.values()):
                stamps.append(float(t))
                frames.append({n: Matrix(quaternion=q[n][rows[n][int(u)]]) for n, u in use.items()})
        devices = raw
    n = len(frames)
    model = lower_body_model()
    if order == "tree":  # parents before children: each joint against its parent's current pose
        frames = [{name: f[name] for name in model.links if name in f} for f in frames]
    heading = imumocap.solvers.calibrate(model, frames[0], mounting=Mounting.Z_BACKWARD)
    rot = {j: [] for j in JOINTS}
    ang = {j: [] for j in JOINTS}
    pelvis = []
    for f in frames:
        model.set_pose_from_imus(f)
        pelvis.append(model.root.joint.rotation.tolist())
        for j, (link, _) in JOINTS.items():
            rot[j].append(model.links[link].joint.rotation.tolist())
            ang[j].append(list(model.joints[j].get()))
    res = {"imumocap": imumocap_version(), "log": str(log), "fps": fps if samples is None else want["rate_hz"],
           "calibration": "frame 0, Mounting.Z_BACKWARD", "heading_deg": float(heading), "first_quaternion_us": first_us,
           "order": order, "timestamps_us": stamps, "samples": "slerp-resampled (ximu3csv.resample)" if samples is None else
           "the raw rows wearpose's nearest-sample grid used",
           "alignment": {j: model.joints[j].alignment.rotation.tolist() for j in JOINTS},
           "rotation": rot, "angles_deg": ang, "pelvis_global": pelvis, "devices": [d.device_name for d in devices]}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res))
    print(f"{res['imumocap']}: {n} frames ({res['samples']}, order {order}: {list(frames[0])}), heading "
          f"{heading:.2f} deg -> {out}")
    del np


def imumocap_version() -> str:
    from importlib.metadata import version

    return f"imumocap {version('imumocap')}, ximu3csv {version('ximu3csv')}"


# ----------------------------------------------------------------------------- part 2 (wearpose)
def zyx_angles_deg(R: Any, A: Any) -> Any:
    """imumocap's ``Joint.get``: ZYX Euler angles of ``A^T R A`` in degrees, ``(..., 3)`` as
    (alpha = about z, beta = about y, gamma = about x). ``R``: ``(..., 3, 3)``, ``A``: ``(3, 3)``."""
    import torch

    from wearpose.geometry import matrix_to_euler

    return torch.rad2deg(matrix_to_euler(A.transpose(-1, -2) @ R @ A, "ZYX"))


def wearpose_run(log: Path, window: tuple[float, float] | None) -> tuple[Any, Any, Any, tuple[str, ...], Any]:
    """The segment estimate of the log (same calls as the CLI): the recording, the track, its
    calibration (recomputed as the estimator does), the sensor names and the grid times (s)."""
    import numpy as np

    from wearpose.calibration import calibrate
    from wearpose.estimators.inputs import nearest_sample_grid
    from wearpose.estimators.segments.estimator import SegmentsEstimator
    from wearpose.recording import from_ximu3

    rec = from_ximu3(log)
    est = SegmentsEstimator(calibration_window=window)
    track = est.estimate(rec)
    names, _ = est._segments(rec)
    grid = nearest_sample_grid(rec.to_canonical(), names)
    cal = calibrate(grid, "tpose", window=tuple(track.extras["calibration_window_s"]), sensors=names)
    return rec, track, cal, names, np.asarray(grid.sensor(names[0]).timestamps, dtype=np.float64)


def samples(log: Path, out: Path) -> None:
    """Part "samples": for every instant of wearpose's grid, the raw timestamp (us) of each
    device's sample the segment estimate used there (nearest valid sample within half a sensor
    period; None where the grid masked it), for ``reference --samples``. Checked against the
    grid: the chosen sample's quaternion is the grid's orientation at that instant."""
    import numpy as np
    import torch

    from wearpose.geometry import geodesic_angle

    rec, track, _, names, grid_t = wearpose_run(log, None)
    from wearpose.estimators.inputs import nearest_sample_grid

    grid = nearest_sample_grid(rec.to_canonical(), names)
    canon = rec.to_canonical()
    devs = {d["device"].lower().replace(" ", "_"): d for d in rec.meta["import"]["devices"]}
    t0_us = min(d["clock_start_us"] for d in devs.values())
    out_dev, mismatch = {}, 0
    for n in names:
        s, g = canon.sensor(n), grid.sensor(n)
        ts = np.asarray(s.timestamps, np.float64)
        i = np.clip(np.searchsorted(ts, grid_t), 1, len(ts) - 1)
        i = np.where(np.abs(ts[i - 1] - grid_t) <= np.abs(ts[i] - grid_t), i - 1, i)
        use = g.valid & s.valid[i] & (np.abs(ts[i] - grid_t) <= 0.5 / float(s.info.rate))
        err = geodesic_angle(torch.from_numpy(np.asarray(s.orientation)[i[use]]).double(),
                             torch.from_numpy(np.asarray(g.orientation)[use]).double())
        mismatch += int((err > 1e-6).sum())
        out_dev[devs[n]["device"]] = [int(round(ts[k] * 1e6)) + t0_us if u else None for k, u in zip(i, use)]
    res = {"rate_hz": float(track.fps), "timestamps_us": [float(t * 1e6 + t0_us) for t in grid_t], "devices": out_dev,
           "mismatched_samples": mismatch}
    out.write_text(json.dumps(res))
    print(f"{len(grid_t)} grid instants, {len(names)} devices, {mismatch} chosen samples differing from the grid -> {out}")


def compare(ref_path: Path, log: Path, out_dir: Path, extra: Sequence[Path] = ()) -> None:
    """Part 2: the RMS table (module doc)."""
    import numpy as np
    import torch

    from wearpose.geometry import SMPL_TO_X_FORWARD_BODY, Z_UP_TO_Y_UP, geodesic_angle, rotation_z
    from wearpose.body.skeleton import JOINT_INDEX

    ref = json.loads(ref_path.read_text())
    S = SMPL_TO_X_FORWARD_BODY
    ref_R = {j: torch.tensor(ref["rotation"][j], dtype=torch.float64) for j in JOINTS}
    ref_A = {j: torch.tensor(ref["alignment"][j], dtype=torch.float64) for j in JOINTS}
    ref_ang = {j: torch.tensor(ref["angles_deg"][j], dtype=torch.float64) for j in JOINTS}
    # Our decomposition reproduces imumocap's own angles from its own rotations (same definition).
    decomp_err = max(float((zyx_angles_deg(ref_R[j], ref_A[j]) - ref_ang[j]).abs().max()) for j in JOINTS)
    runs = []
    cases = []
    main_ref = ref
    for r, tag in [(ref, "")] + [(json.loads(p.read_text()), "") for p in extra]:
        tag = "" if r is ref else f"imumocap {r['order']} order, {'slerp 30 Hz' if r['samples'].startswith('slerp') else 'wearpose samples'}: "
        t1 = (r["timestamps_us"][0] - r["first_quaternion_us"]) / 1e6
        cal_window = (t1, t1 + 0.1)
        cases += [(r, tag + "same instant + same body axes", cal_window, True)] if tag else \
            [(r, "as shipped", None, False), (r, "same calibration instant", cal_window, False),
             (r, "same instant + same body axes", cal_window, True)]
    for ref, label, window, same_axes in cases:
        ref_R = {j: torch.tensor(ref["rotation"][j], dtype=torch.float64) for j in JOINTS}
        ref_ang = {j: torch.tensor(ref["angles_deg"][j], dtype=torch.float64) for j in JOINTS}
        rec, track, cal, names, grid_t = wearpose_run(log, window)
        t0_us = min(d["clock_start_us"] for d in rec.meta["import"]["devices"])
        t_ref = (np.asarray(ref["timestamps_us"]) - t0_us) / 1e6
        idx = np.clip(np.searchsorted(grid_t, t_ref), 1, len(grid_t) - 1)
        idx = np.where(np.abs(grid_t[idx - 1] - t_ref) <= np.abs(grid_t[idx] - t_ref), idx - 1, idx)
        ok = (np.abs(grid_t[idx] - t_ref) <= 0.5 / track.fps) & track.valid.numpy()[idx]
        D = torch.eye(3, dtype=torch.float64)
        axes_deg, axes_yaw_deg, axes_tilt_deg = 0.0, 0.0, 0.0
        if same_axes:
            pel = names.index("pelvis")
            C = cal.world_rotation[pel].double() @ Z_UP_TO_Y_UP  # AHRS (Z-up) world -> wearpose world
            E = C.T @ S.T  # wearpose's body axes at calibration in the AHRS world (x fwd, y left, z up)
            D = rotation_z(torch.tensor(math.radians(ref["heading_deg"]), dtype=torch.float64)).T @ E
            axes_deg = math.degrees(float(geodesic_angle(D, torch.eye(3, dtype=torch.float64))))
            axes_yaw_deg = math.degrees(math.atan2(float(D[1, 0]), float(D[0, 0])))  # heading part (about up)
            axes_tilt_deg = math.degrees(math.acos(min(1.0, float(D[2, 2]))))  # the up axes' disagreement
        dt = 1.0 / float(ref["fps"])
        # The whole body's turning rate: the pelvis heading rate (deg/s) in imumocap's solution.
        P = torch.tensor(ref["pelvis_global"], dtype=torch.float64)
        yaw = torch.atan2(P[:, 1, 0], P[:, 0, 0])
        yaw_rate = torch.zeros(len(P), dtype=torch.float64)
        yaw_rate[1:-1] = torch.rad2deg(torch.remainder(yaw[2:] - yaw[:-2] + math.pi, 2 * math.pi) - math.pi).abs() / (2 * dt)
        turning = (yaw_rate >= SLOW_DEG_S)[torch.from_numpy(ok)]
        rows = {}
        for j, (_, smpl) in JOINTS.items():
            L = track.local_rot[idx, JOINT_INDEX[smpl]].double()
            R = D @ (S @ L @ S.T) @ D.T  # imumocap link axes
            ang = zyx_angles_deg(R, ref_A[j])
            d = (ang - ref_ang[j])[torch.from_numpy(ok)]
            d = (d + 180.0) % 360.0 - 180.0
            geo = torch.rad2deg(geodesic_angle(R[torch.from_numpy(ok)], ref_R[j][torch.from_numpy(ok)]))
            # Residual vs motion: the reference joint's angular speed (deg/s, central difference).
            Rr = ref_R[j]
            speed = torch.zeros(len(Rr), dtype=torch.float64)
            speed[1:-1] = torch.rad2deg(geodesic_angle(Rr[:-2], Rr[2:])) / (2 * dt)
            sp = speed[torch.from_numpy(ok)]
            slow = sp < SLOW_DEG_S
            rows[j] = {"gamma_rms_turning_deg": float(d[turning, 2].pow(2).mean().sqrt()),
                       "gamma_rms_not_turning_deg": float(d[~turning, 2].pow(2).mean().sqrt()),
                       "frames_turning": int(turning.sum()),
                       "geodesic_rms_slow_deg": float(geo[slow].pow(2).mean().sqrt()),
                       "geodesic_rms_fast_deg": float(geo[~slow].pow(2).mean().sqrt()),
                       "frames_slow": int(slow.sum()), "speed_p95_deg_s": float(sp.quantile(0.95)),
                       "rms_deg": {a: float(d[:, k].pow(2).mean().sqrt()) for k, a in enumerate(AXES)},
                       "max_abs_deg": {a: float(d[:, k].abs().max()) for k, a in enumerate(AXES)},
                       "mean_deg": {a: float(d[:, k].mean()) for k, a in enumerate(AXES)},
                       "geodesic_rms_deg": float(geo.pow(2).mean().sqrt()),
                       "ref_range_deg": {a: float(ref_ang[j][:, k].max() - ref_ang[j][:, k].min()) for k, a in enumerate(AXES)}}
        runs.append({"alignment": label, "reference_samples": ref["samples"],
                     "wearpose_calibration_window_s": track.extras["calibration_window_s"],
                     "body_axes_rotation_deg": axes_deg, "body_axes_yaw_deg": axes_yaw_deg,
                     "body_axes_tilt_deg": axes_tilt_deg, "frames_compared": int(ok.sum()), "frames_reference": len(t_ref),
                     "joints": rows})
        print(label, int(ok.sum()), {j: round(r["geodesic_rms_deg"], 2) for j, r in rows.items()})
    res = {"reference": {k: main_ref[k] for k in ("imumocap", "fps", "calibration", "heading_deg", "order", "devices")},
           "log": str(log), "decomposition_check_max_abs_deg": decomp_err, "runs": runs,
           "command": "benchmarks/imumocap_compare.py: reference, reference --order tree, samples, reference --samples "
                      "(file and tree order), compare --also (module doc)"}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "imumocap_compare.json").write_text(json.dumps(res, indent=1))
    (out_dir / "imumocap_compare.md").write_text(markdown(res))
    print(markdown(res))


def markdown(res: dict[str, Any]) -> str:
    """The table: RMS per joint and axis for each alignment."""
    r0 = res["reference"]
    md = [f"Segment estimate vs {r0['imumocap']} on the real x-IMU3 lower-body log; imumocap at {r0['fps']} Hz, "
          f"calibrated on its {r0['calibration']} (heading {r0['heading_deg']:.2f} deg), IMUs applied in {r0['order']} order "
          f"as x-io's example does ({', '.join(r0['devices'])}). Angles as imumocap's "
          "`Joint.get()` (ZYX Euler of the aligned joint rotation: alpha about z, beta about y, gamma about x), degrees. "
          f"Decomposition check (ours on imumocap's rotations vs its angles): {res['decomposition_check_max_abs_deg']:.2g} deg.",
          "", "| alignment | frames | joint | RMS alpha | RMS beta | RMS gamma | geodesic RMS | mean alpha / beta / gamma | "
          "imumocap range alpha / beta / gamma | geodesic RMS slow / fast (frames slow) | "
          "RMS gamma, pelvis turning / not (frames turning) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for run in res["runs"]:
        lab = run["alignment"] + (f" (D: {run['body_axes_rotation_deg']:.2f} deg, yaw {run['body_axes_yaw_deg']:.2f}, "
                                  f"tilt {run['body_axes_tilt_deg']:.2f})" if run["body_axes_rotation_deg"] else "")
        for j, r in run["joints"].items():
            m, rg = r["mean_deg"], r["ref_range_deg"]
            md.append(f"| {lab} | {run['frames_compared']}/{run['frames_reference']} | {j} | {r['rms_deg']['alpha']:.2f} | "
                      f"{r['rms_deg']['beta']:.2f} | {r['rms_deg']['gamma']:.2f} | {r['geodesic_rms_deg']:.2f} | "
                      f"{m['alpha']:.2f} / {m['beta']:.2f} / {m['gamma']:.2f} | {rg['alpha']:.0f} / {rg['beta']:.0f} / {rg['gamma']:.0f} | "
                      f"{r['geodesic_rms_slow_deg']:.2f} / {r['geodesic_rms_fast_deg']:.2f} ({r['frames_slow']}) | "
                      f"{r['gamma_rms_turning_deg']:.2f} / {r['gamma_rms_not_turning_deg']:.2f} ({r['frames_turning']}) |")
    md += ["", f"Slow: the imumocap joint turns slower than {SLOW_DEG_S:g} deg/s at that frame. Turning: imumocap's "
           f"pelvis heading changes faster than {SLOW_DEG_S:g} deg/s. Frames: imumocap's instants with a valid wearpose "
           "grid frame within half a grid period. alpha ~ flexion/extension (about the left axis), beta ~ "
           "ab/adduction (about the forward axis), gamma ~ axial rotation (about the segment's long axis)."]
    return "\n".join(md) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="part", required=True)
    r = sub.add_parser("reference", help="imumocap's angles (run with the Python 3.12 venv)")
    r.add_argument("--log", type=Path, default=LOG)
    r.add_argument("--fps", type=float, default=30.0, help="imumocap's resampling rate (x-io's example: 30)")
    r.add_argument("--out", type=Path, default=Path("/tmp/imumocap_angles.json"))
    r.add_argument("--samples", type=Path, default=None, help="the rows wearpose used (part samples), no resampling")
    r.add_argument("--order", choices=("file", "tree"), default="file",
                   help="IMUs applied per frame in folder order (x-io's example) or parents first")
    sm = sub.add_parser("samples", help="the raw rows wearpose's grid uses, for reference --samples (wearpose's venv)")
    sm.add_argument("--log", type=Path, default=LOG)
    sm.add_argument("--out", type=Path, default=Path("/tmp/wearpose_samples.json"))
    c = sub.add_parser("compare", help="the segment estimate against the reference file (wearpose's venv)")
    c.add_argument("--reference", type=Path, default=Path("/tmp/imumocap_angles.json"))
    c.add_argument("--log", type=Path, default=LOG)
    c.add_argument("--out", type=Path, default=HERE / "results")
    c.add_argument("--also", type=Path, nargs="*", default=[], help="more reference files (--order tree, --samples): "
                   "one aligned row each, the diagnostics of the residual")
    a = ap.parse_args()
    if a.part == "reference":
        if sys.version_info < (3, 12):
            sys.exit("the reference part needs Python >= 3.12 with imumocap==1.4.0 and ximu3csv==1.0.5 (module doc)")
        reference(a.log.resolve(), a.fps, a.out, a.samples, a.order)
    elif a.part == "samples":
        samples(a.log.resolve(), a.out)
    else:
        compare(a.reference, a.log.resolve(), a.out, a.also)


if __name__ == "__main__":
    main()
