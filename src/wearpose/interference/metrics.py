"""Detection metrics of MI-Poser Sec. 6.2 (Fig. 8, Table 3): MCC, F1, precision, recall.

Ground truth: a frame is interfered when its EM position error exceeds ``e_P`` (the paper uses
position error as the criterion, ``e_P = 0.1`` m in Table 3). MCC (Chicco & Jurman 2020) because
interfered frames are rare.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


def binary_metrics(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """MCC, F1, precision, recall, positive ratio of boolean arrays (any shape).

    Undefined ratios (no predicted or no true positives) are 0, as scikit-learn reports them.
    """
    p = np.asarray(pred, dtype=bool).ravel()
    y = np.asarray(truth, dtype=bool).ravel()
    tp = float(np.sum(p & y))
    tn = float(np.sum(~p & ~y))
    fp = float(np.sum(p & ~y))
    fn = float(np.sum(~p & y))
    prec = tp / (tp + fp) if tp + fp > 0 else 0.0
    rec = tp / (tp + fn) if tp + fn > 0 else 0.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    den = np.sqrt((tp + fp) * (tp + fn) * (tn + fp) * (tn + fn))
    mcc = (tp * tn - fp * fn) / den if den > 0 else 0.0
    return {"mcc": float(mcc), "f1": f1, "precision": prec, "recall": rec,
            "positive_ratio": float(y.mean()) if y.size else 0.0, "frames": int(y.size)}


def sweep_detection(preds: dict[float, np.ndarray], errors: np.ndarray, e_p: Sequence[float]) -> list[dict[str, float]]:
    """For each ground-truth threshold ``e_P`` (m): the detection threshold with the best MCC.

    Args:
        preds: detection threshold (deg) -> ``(N,)`` bool flags (all frames concatenated).
        errors: ``(N,)`` position error, m.
        e_p: ground-truth thresholds, m.

    Returns:
        one row per ``e_P``: ``e_p_m``, ``best_threshold_deg`` and its metrics.
    """
    rows = []
    for e in e_p:
        y = errors > e
        best = None
        for th, f in sorted(preds.items()):
            m = binary_metrics(f, y)
            if best is None or m["mcc"] > best["mcc"]:
                best = {"e_p_m": float(e), "best_threshold_deg": float(th), **m}
        rows.append(best)
    return rows
