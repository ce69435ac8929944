#!/usr/bin/env python3
"""ATE and RPE with evo (github.com/MichaelGrupp/evo) for tests/it/metrics.rs.

Usage: evo_crosscheck.py TRUTH.txt EST.txt OUT.json. Both files are TUM trajectories
(timestamp tx ty tz qx qy qz qw, identity orientations); the estimate may lack epochs
the truth has. Exit status 3 when evo is missing.

OUT gets, each as {"mean", "rmse", "median", "std", "max", "count"} of the translation
errors in metres:

  ape, ape_aligned            evo's APE (translation part) without and with its Umeyama
                              alignment (no scale), as `evo_ape tum T E [--align]`;
  rpe_frames, rpe_frames_aligned
                              evo's RPE (translation part, delta 1 frame, consecutive
                              pairs) on the whole file, as `evo_rpe tum T E [--align]`;
                              it pairs consecutive lines, so also the two epochs either
                              side of a gap;
  rpe_segments                the same RPE run on each gap-free stretch and pooled: the
                              pairs exactly 1 s apart, i.e. pairing by time;
  rpe_segments_positions_aligned
                              as rpe_segments, on the estimate whose positions (only)
                              were moved by evo's Umeyama rotation and translation;
  rpe_segments_13             evo's RPE over 13 frames with all pairs (i, i + 13) on
                              each gap-free stretch, pooled: the pairs exactly 13 s
                              apart (a world's `[scoring] rpe_delta_s = 13`);

plus "rotation" (3x3, rows) and "translation" of that alignment, and "gaps" (the
number of places where consecutive estimate epochs are more than 1.5 s apart).
"""
import json
import sys

try:
    import numpy as np
    from evo.core import geometry, metrics, sync
    from evo.core.trajectory import PoseTrajectory3D
    from evo.tools import file_interface
except ImportError:
    sys.exit(3)


def stats(metric):
    s = metric.get_all_statistics()
    return {
        "mean": float(s["mean"]),
        "rmse": float(s["rmse"]),
        "median": float(s["median"]),
        "std": float(s["std"]),
        "max": float(s["max"]),
        "count": int(metric.error.size),
    }


def ape(ref, est):
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((ref, est))
    return m


def rpe(ref, est, delta=1):
    m = metrics.RPE(
        metrics.PoseRelation.translation_part,
        delta=delta,
        delta_unit=metrics.Unit.frames,
        all_pairs=delta > 1,
    )
    m.process_data((ref, est))
    return m


def sub(traj, idx):
    """The poses idx of traj as a new trajectory."""
    return PoseTrajectory3D(
        positions_xyz=traj.positions_xyz[idx],
        orientations_quat_wxyz=traj.orientations_quat_wxyz[idx],
        timestamps=traj.timestamps[idx],
    )


def rpe_by_segments(ref, est, delta=1):
    """RPE over each gap-free stretch, errors pooled into one metric-like object."""
    t = est.timestamps
    breaks = np.flatnonzero(np.diff(t) > 1.5) + 1
    errors = []
    for idx in np.split(np.arange(t.size), breaks):
        if idx.size > delta:
            errors.append(rpe(sub(ref, idx), sub(est, idx), delta).error)
    pooled = metrics.RPE(metrics.PoseRelation.translation_part)
    pooled.error = np.concatenate(errors)
    return pooled, breaks.size


def main():
    truth = file_interface.read_tum_trajectory_file(sys.argv[1])
    est = file_interface.read_tum_trajectory_file(sys.argv[2])
    # Keep the truth epochs that have an estimate, as evo_ape and evo_rpe do.
    ref, est = sync.associate_trajectories(truth, est, max_diff=0.01)
    out = {"ape": stats(ape(ref, est)), "rpe_frames": stats(rpe(ref, est))}
    seg, gaps = rpe_by_segments(ref, est)
    out["rpe_segments"] = stats(seg)
    out["rpe_segments_13"] = stats(rpe_by_segments(ref, est, 13)[0])
    out["gaps"] = int(gaps)

    # evo's own alignment of the estimate (rotation and translation, no scale).
    aligned = PoseTrajectory3D(
        poses_se3=est.poses_se3, timestamps=est.timestamps
    )
    r, t, _ = aligned.align(ref, correct_scale=False)
    out["rotation"] = np.asarray(r).tolist()
    out["translation"] = np.asarray(t).tolist()
    out["ape_aligned"] = stats(ape(ref, aligned))
    out["rpe_frames_aligned"] = stats(rpe(ref, aligned))

    # The positions moved by the same transformation, orientations left at identity.
    moved = PoseTrajectory3D(
        positions_xyz=(r @ est.positions_xyz.T).T + t,
        orientations_quat_wxyz=est.orientations_quat_wxyz,
        timestamps=est.timestamps,
    )
    out["rpe_segments_positions_aligned"] = stats(rpe_by_segments(ref, moved)[0])

    # Cross-check of the alignment itself with evo's Umeyama on the raw positions.
    r2, t2, _ = geometry.umeyama_alignment(
        est.positions_xyz.T, ref.positions_xyz.T, False
    )
    out["umeyama_rotation"] = np.asarray(r2).tolist()
    out["umeyama_translation"] = np.asarray(t2).tolist()

    with open(sys.argv[3], "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()
