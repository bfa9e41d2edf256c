"""Score detection output against simulator ground truth (pure: numpy in, dict out).

Ground truth (simulator contract): ``surface`` and ``object`` (N,) int32, -1 for none.
Predictions (``supportnode detect``'s labels.npz): ``surface`` and ``object`` (N,) int32 per
input point in input order, -1 for none. Support, when both sides have it: the truth's
``supported_by`` (N,) per point (the object each point's object stands on, -1 on a surface) and
the prediction's ``supported_by`` (C,) per cluster id (result.json's objects: the cluster each
stands on, -1 on a surface). All counts are points; every value in the result is a
plain Python int, float, list or dict, ready for JSON.
"""

from __future__ import annotations

import numpy as np

from supportnode.errors import InputError

__all__ = ["adjusted_rand_index", "contingency", "evaluate", "format_support", "supported_by_of"]

MATCH_IOU = 0.5  # a GT surface is found by a predicted one with at least this IoU
MAJORITY = 0.5  # object found: majority cluster holds >= this of it and is >= this the object
SPLIT_SHARE = 0.2  # object split: >= 2 predicted clusters each hold >= this share of it


def contingency(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct label pairs of two (N,) integer labelings and how many points carry each.

    Returns ``(a_values (P,), b_values (P,), counts (P,) int64)`` sorted by a, then b."""
    pairs = np.stack([np.asarray(a, np.int64), np.asarray(b, np.int64)], axis=1)
    if pairs.shape[0] == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e
    uniq, counts = np.unique(pairs, axis=0, return_counts=True)
    return uniq[:, 0], uniq[:, 1], counts.astype(np.int64)


def _pairs(n: np.ndarray) -> float:
    n = np.asarray(n, dtype=np.float64)
    return float((n * (n - 1.0) / 2.0).sum())


def adjusted_rand_index(truth: np.ndarray, pred: np.ndarray) -> float:
    """Adjusted Rand index (Hubert and Arabie) of two (N,) labelings; 1.0 for identical
    partitions (up to renaming), about 0 for chance. Two trivial partitions score 1.0."""
    truth = np.asarray(truth)
    pred = np.asarray(pred)
    n = truth.shape[0]
    if n < 2:
        return 1.0
    _, _, nij = contingency(truth, pred)
    _, a = np.unique(truth, return_counts=True)
    _, b = np.unique(pred, return_counts=True)
    index = _pairs(nij)
    sa, sb, total = _pairs(a), _pairs(b), n * (n - 1) / 2.0
    expected = sa * sb / total
    top = 0.5 * (sa + sb)
    if top == expected:  # both partitions trivial (all one cluster, or all singletons)
        return 1.0
    return float((index - expected) / (top - expected))


def supported_by_of(objects: list) -> np.ndarray | None:
    """(C,) int64 supported_by per cluster id from result.json's ``objects`` (each a dict with
    an integer ``id`` and ``supported_by``, -1 on a surface); None when any object lacks the
    field (results from before it). InputError naming the object when one is malformed."""
    if not objects or any(not isinstance(o, dict) or "supported_by" not in o for o in objects):
        return None
    by = np.full(len(objects), -1, np.int64)
    for i, o in enumerate(objects):
        ids = (o.get("id"), o["supported_by"])
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in ids) or not (
            0 <= ids[0] < len(objects)
        ):
            raise InputError(
                f"objects[{i}]: expected an integer id and supported_by (-1: a surface)"
            )
        by[ids[0]] = ids[1]
    return by


def format_support(support: dict | None) -> str:
    """'right/objects (stacked right/stacked)' of evaluate()'s objects["support"], or '-'
    when the detection (or the truth) has no supported_by."""
    if support is None:
        return "-"
    return (
        f"{support['correct']}/{support['total']} "
        f"(stacked {support['stacked_correct']}/{support['stacked_total']})"
    )


def _check(name: str, arr: np.ndarray, n: int | None) -> np.ndarray:
    a = np.asarray(arr)
    if a.ndim != 1 or not np.issubdtype(a.dtype, np.integer):
        raise InputError(f"{name} must be a 1-D integer array, got {a.dtype} {a.shape}")
    if n is not None and a.shape[0] != n:
        raise InputError(f"{name} has {a.shape[0]} labels, expected {n}")
    return a.astype(np.int64)


def _surface_scores(ps: np.ndarray, gs: np.ndarray) -> dict:
    pred_on, gt_on = ps >= 0, gs >= 0
    tp = int((pred_on & gt_on).sum())
    n_pred, n_gt = int(pred_on.sum()), int(gt_on.sum())
    precision = tp / n_pred if n_pred else (1.0 if n_gt == 0 else 0.0)
    recall = tp / n_gt if n_gt else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0

    gt_ids, gt_size = np.unique(gs[gt_on], return_counts=True)
    pr_ids, pr_size = np.unique(ps[pred_on], return_counts=True)
    both = pred_on & gt_on
    g, p, inter = contingency(gs[both], ps[both])
    union = gt_size[np.searchsorted(gt_ids, g)] + pr_size[np.searchsorted(pr_ids, p)] - inter
    iou = inter / np.maximum(union, 1)
    best_gt = np.zeros(gt_ids.size)
    np.maximum.at(best_gt, np.searchsorted(gt_ids, g), iou)
    best_pr = np.zeros(pr_ids.size)
    np.maximum.at(best_pr, np.searchsorted(pr_ids, p), iou)
    return {
        "points_gt": n_gt,
        "points_pred": n_pred,
        "precision": float(precision),
        "recall": float(recall),
        "f1": float(f1),
        "gt_count": int(gt_ids.size),
        "pred_count": int(pr_ids.size),
        "best_iou": {int(k): round(float(v), 6) for k, v in zip(gt_ids, best_gt, strict=True)},
        "mean_iou": float(best_gt.mean()) if best_gt.size else 1.0,
        "found": int((best_gt >= MATCH_IOU).sum()),
        "spurious": int((best_pr < MATCH_IOU).sum()),
        "spurious_ids": [int(k) for k in pr_ids[best_pr < MATCH_IOU]],
    }


def _object_scores(po: np.ndarray, go: np.ndarray) -> tuple[dict, np.ndarray, np.ndarray]:
    """Object scores, the cluster matched to each GT object (its majority cluster when found,
    else -1) and the GT object ids, both (G,)."""
    on = go >= 0
    gt_obj, pred = go[on], po[on]
    # Points no cluster claims are singletons for the ARI: being missed together is not
    # agreement. Fresh negative ids keep them apart from each other and from real clusters.
    pred_ari = np.where(pred >= 0, pred, -1 - np.arange(pred.size))
    ari = adjusted_rand_index(gt_obj, pred_ari) if gt_obj.size else 1.0

    gt_ids, gt_size = np.unique(gt_obj, return_counts=True)
    cl_ids, cl_size = np.unique(po[po >= 0], return_counts=True)  # cluster sizes, all points
    claimed = pred >= 0
    g, c, n = contingency(gt_obj[claimed], pred[claimed])
    gi = np.searchsorted(gt_ids, g)
    share = n / gt_size[gi]
    # Majority cluster per GT object: sort by object, then count descending; first per object.
    order = np.lexsort((-n, gi))
    first = order[np.r_[True, gi[order][1:] != gi[order][:-1]]] if order.size else order
    maj_cluster = np.full(gt_ids.size, -1, dtype=np.int64)
    maj_count = np.zeros(gt_ids.size, dtype=np.int64)
    maj_cluster[gi[first]] = c[first]
    maj_count[gi[first]] = n[first]
    has = maj_cluster >= 0
    maj_size = np.zeros(gt_ids.size, dtype=np.int64)
    maj_size[has] = cl_size[np.searchsorted(cl_ids, maj_cluster[has])]
    found = (
        has & (maj_count >= MAJORITY * gt_size) & (maj_count >= MAJORITY * np.maximum(maj_size, 1))
    )

    # Merged: GT objects whose majority cluster is also another GT object's majority cluster.
    _, inv, per = np.unique(maj_cluster[has], return_inverse=True, return_counts=True)
    merged = np.zeros(gt_ids.size, dtype=bool)
    merged[np.flatnonzero(has)] = per[inv.reshape(-1)] >= 2
    groups = [
        sorted(int(x) for x in gt_ids[has][inv.reshape(-1) == j]) for j in np.flatnonzero(per >= 2)
    ]
    # Split: two or more clusters each hold >= SPLIT_SHARE of the object.
    big = np.bincount(gi[share >= SPLIT_SHARE], minlength=gt_ids.size)
    split = big >= 2
    scores = {
        "points_gt": int(on.sum()),
        "gt_count": int(gt_ids.size),
        "pred_count": int(cl_ids.size),
        "ari": float(ari),
        "found": int(found.sum()),
        "merged": int(merged.sum()),
        "split": int(split.sum()),
        "missed": int((~has).sum()),
        "merged_groups": groups,
        "found_ids": [int(x) for x in gt_ids[found]],
        "split_ids": [int(x) for x in gt_ids[split]],
    }
    return scores, np.where(found, maj_cluster, -1), gt_ids


def _support_scores(
    matched: np.ndarray, gt_ids: np.ndarray, go: np.ndarray, gby: np.ndarray, pby: np.ndarray
) -> dict:
    """Objects whose matched cluster stands on the cluster matched to the true supporter (or
    on a surface, -1, as the truth says). matched: (G,) cluster of each found GT object (-1 if
    not found); gt_ids (G,); go, gby: (N,) truth per point; pby: (C,) per cluster."""
    on = go >= 0
    true_by = np.full(gt_ids.size, -1, np.int64)
    true_by[np.searchsorted(gt_ids, go[on])] = gby[on]  # one value per object
    cluster_of = dict(zip(gt_ids.tolist(), matched.tolist(), strict=True))
    want = np.array([-1 if t < 0 else cluster_of.get(int(t), -1) for t in true_by], np.int64)
    # A supporter that is not found has no cluster to point at: that object cannot be right.
    possible = (true_by < 0) | (want >= 0)
    has = matched >= 0
    got = np.full(gt_ids.size, -2, np.int64)
    got[has] = pby[matched[has]]
    ok = has & possible & (got == want)
    stacked = true_by >= 0
    return {
        "correct": int(ok.sum()),
        "total": int(gt_ids.size),
        "accuracy": float(ok.mean()) if gt_ids.size else 1.0,
        "stacked_correct": int((ok & stacked).sum()),
        "stacked_total": int(stacked.sum()),
    }


def evaluate(
    pred_surface: np.ndarray,
    pred_object: np.ndarray,
    gt_surface: np.ndarray,
    gt_object: np.ndarray,
    gt_supported_by: np.ndarray | None = None,
    pred_supported_by: np.ndarray | None = None,
) -> dict:
    """Surface and object scores of one prediction; all four arrays (N,) integer, -1 = none.

    Returns ``{"points": N, "surfaces": {...}, "objects": {...}}``:
    surfaces: point precision/recall/F1 (a point is a surface point if its label >= 0), per
    GT surface best IoU and their mean, ``found`` (best IoU >= 0.5), ``spurious`` (predicted
    surfaces with no GT surface at IoU >= 0.5) and their ids.
    objects (over the points of GT objects only): adjusted Rand index (unclaimed points are
    singletons), ``found`` (majority cluster holds >= 50% of the object and is >= 50% this
    object), ``merged`` (objects sharing their majority cluster with another) and
    ``merged_groups`` (lists of GT object ids), ``split`` (>= 2 clusters each holding >= 20%
    of the object), ``missed`` (no point claimed by any cluster), and ``support`` when both
    supported_by arrays are given (else None): ``correct`` of ``total`` GT objects are found
    and their cluster's supported_by is the cluster of the object they stand on (-1 on a
    surface), ``accuracy``, and the same for the stacked ones (``stacked_correct`` of
    ``stacked_total``, those standing on an object).
    """
    gs = _check("gt_surface", gt_surface, None)
    n = gs.shape[0]
    go = _check("gt_object", gt_object, n)
    ps = _check("pred_surface", pred_surface, n)
    po = _check("pred_object", pred_object, n)
    objects, matched, gt_ids = _object_scores(po, go)
    objects["support"] = None
    if gt_supported_by is not None and pred_supported_by is not None:
        gby = _check("gt_supported_by", gt_supported_by, n)
        pby = _check("pred_supported_by", pred_supported_by, None)
        clusters = int(po.max(initial=-1)) + 1
        if pby.shape[0] < clusters or (pby.size and (pby.min() < -1 or pby.max() >= pby.size)):
            raise InputError(
                f"pred_supported_by must give each of the {clusters} clusters a cluster id or -1"
            )
        objects["support"] = _support_scores(matched, gt_ids, go, gby, pby)
    return {"points": int(n), "surfaces": _surface_scores(ps, gs), "objects": objects}
