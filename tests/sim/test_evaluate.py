"""Scores of hand-made labelings and the `supportnode eval` command."""

from __future__ import annotations

import json

import numpy as np
import pytest

from supportnode.errors import InputError
from supportnode.sim.evaluate import adjusted_rand_index, evaluate

# 12 points: GT surfaces 0 (points 0-3) and 1 (4-5); GT objects 0 (6-8) and 1 (9-11).
GT_SURFACE = np.array([0, 0, 0, 0, 1, 1, -1, -1, -1, -1, -1, -1])
GT_OBJECT = np.array([-1, -1, -1, -1, -1, -1, 0, 0, 0, 1, 1, 1])


def test_perfect_prediction_with_renamed_ids() -> None:
    ps = np.where(GT_SURFACE >= 0, 5 - GT_SURFACE, -1)
    po = np.where(GT_OBJECT >= 0, 7 + GT_OBJECT, -1)
    r = evaluate(ps, po, GT_SURFACE, GT_OBJECT)
    s, o = r["surfaces"], r["objects"]
    assert s["precision"] == 1.0 and s["recall"] == 1.0 and s["f1"] == 1.0
    assert s["found"] == 2 and s["spurious"] == 0 and s["mean_iou"] == 1.0
    assert o["ari"] == 1.0 and o["found"] == 2 and o["merged"] == 0 and o["split"] == 0
    json.dumps(r)  # plain Python types only


def test_all_objects_merged() -> None:
    po = np.where(GT_OBJECT >= 0, 3, -1)
    po[5] = 3  # the merged cluster also takes a surface point: 7 points, 3 of each object
    r = evaluate(GT_SURFACE, po, GT_SURFACE, GT_OBJECT)["objects"]
    assert r["ari"] == pytest.approx(0.0)
    assert r["merged"] == 2 and r["merged_groups"] == [[0, 1]]
    assert r["found"] == 0  # each object is 3/7 < 50% of the cluster
    assert r["split"] == 0


def test_all_objects_split() -> None:
    po = np.full(12, -1)
    po[6:12] = [0, 0, 1, 2, 2, 3]  # each object over two clusters, each >= 20% of it
    r = evaluate(GT_SURFACE, po, GT_SURFACE, GT_OBJECT)["objects"]
    assert r["split"] == 2 and r["merged"] == 0
    assert r["found"] == 2  # majority clusters hold 2 of 3 points and are pure


def test_known_ari_by_hand() -> None:
    # truth {0,1,2}{3,4,5}, pred {0,1}{2,3}{4,5}: index 2, expected 6*3/15 = 1.2, max 4.5
    ari = adjusted_rand_index(np.array([0, 0, 0, 1, 1, 1]), np.array([0, 0, 1, 1, 2, 2]))
    assert ari == pytest.approx((2 - 1.2) / (4.5 - 1.2))
    assert adjusted_rand_index(np.array([1, 1, 2]), np.array([9, 9, 4])) == 1.0


def test_surfaces_partial_and_spurious() -> None:
    ps = np.full(12, -1)
    ps[0:2] = 0  # half of GT surface 0: IoU 0.5 -> found
    ps[4:8] = 1  # GT surface 1 plus two object points: IoU 2/4 = 0.5 -> found
    ps[9:11] = 2  # object points only: spurious
    s = evaluate(ps, np.full(12, -1), GT_SURFACE, GT_OBJECT)["surfaces"]
    assert s["precision"] == pytest.approx(4 / 8) and s["recall"] == pytest.approx(4 / 6)
    assert s["best_iou"] == {0: 0.5, 1: 0.5}
    assert s["found"] == 2 and s["spurious"] == 1 and s["spurious_ids"] == [2]


def test_unclaimed_points_are_singletons() -> None:
    r = evaluate(GT_SURFACE, np.full(12, -1), GT_SURFACE, GT_OBJECT)["objects"]
    assert r["ari"] == pytest.approx(0.0) and r["missed"] == 2 and r["found"] == 0


def test_length_mismatch_raises() -> None:
    with pytest.raises(InputError, match="pred_surface has 3 labels, expected 12"):
        evaluate(np.zeros(3, int), np.zeros(12, int), GT_SURFACE, GT_OBJECT)


@pytest.fixture
def result_dir(tmp_path):
    d = tmp_path / "out"
    d.mkdir()
    np.savez(
        d / "labels.npz", surface=GT_SURFACE.astype(np.int32), object=GT_OBJECT.astype(np.int32)
    )
    return d


def _main(argv: list[str]) -> int:
    cli = pytest.importorskip("supportnode.cli")
    return cli.main(argv)


def test_cli_eval_npz_truth(tmp_path, result_dir, capsys) -> None:
    gt = tmp_path / "gt.npz"
    np.savez(
        gt,
        role=np.where(GT_SURFACE >= 0, 0, 2).astype(np.int8),
        primitive=np.zeros(12, np.int32),
        object=GT_OBJECT.astype(np.int32),
        surface=GT_SURFACE.astype(np.int32),
    )
    out = tmp_path / "scores.json"
    assert _main(["eval", str(result_dir), str(gt), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "surface F1" in text and "object ARI" in text
    scores = json.loads(out.read_text())
    assert scores["surfaces"]["f1"] == 1.0 and scores["objects"]["ari"] == 1.0


def test_cli_eval_ply_truth(tmp_path, result_dir) -> None:
    clouds = pytest.importorskip("supportnode.io.clouds")
    gt = tmp_path / "gt.ply"
    clouds.write_ply(
        gt,
        np.random.default_rng(0).random((12, 3)),
        fields={"object": GT_OBJECT.astype(np.int32), "surface": GT_SURFACE.astype(np.int32)},
    )
    assert _main(["eval", str(result_dir), str(gt)]) == 0


def test_cli_eval_count_mismatch(tmp_path, result_dir, capsys) -> None:
    gt = tmp_path / "gt.npz"
    np.savez(gt, object=np.zeros(5, np.int32), surface=np.zeros(5, np.int32))
    assert _main(["eval", str(result_dir), str(gt)]) == 2
    err = capsys.readouterr().err
    assert "labels.npz has 12 labels" in err and "gt.npz has 5 points" in err


# Support: GT object 0 on a surface, 1 standing on 0, 2 on a surface (points 0-2: table).
SUP_OBJECT = np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1, 2, 2, 2])
SUP_BY = np.array([-1, -1, -1, -1, -1, -1, 0, 0, 0, -1, -1, -1])
SUP_SURFACE = np.array([0, 0, 0] + [-1] * 9)
# Clusters renamed: object 1 -> cluster 0, object 2 -> 1, object 0 -> 2.
SUP_PRED = np.array([-1, -1, -1, 2, 2, 2, 0, 0, 0, 1, 1, 1])


def test_supported_by_scores() -> None:
    def support(pred, by):
        return evaluate(SUP_SURFACE, pred, SUP_SURFACE, SUP_OBJECT, SUP_BY, np.array(by))[
            "objects"
        ]["support"]

    right = support(SUP_PRED, [2, -1, -1])
    assert right == {
        "correct": 3,
        "total": 3,
        "accuracy": 1.0,
        "stacked_correct": 1,
        "stacked_total": 1,
    }
    flat = support(SUP_PRED, [-1, -1, -1])  # a stack taken as standing on the table
    assert (flat["correct"], flat["stacked_correct"]) == (2, 0)
    wrong = support(SUP_PRED, [1, -1, 0])  # on the wrong object; a surface object on another
    assert (wrong["correct"], wrong["stacked_correct"]) == (1, 0)
    # The supporter lost (its points claimed by no cluster): the top box cannot be right.
    lost = support(np.where(SUP_OBJECT == 0, -1, SUP_PRED), [-1, -1, -1])
    assert (lost["correct"], lost["stacked_correct"]) == (1, 0)
    assert evaluate(SUP_SURFACE, SUP_PRED, SUP_SURFACE, SUP_OBJECT)["objects"]["support"] is None
    for bad in ([2, -1], [3, -1, -1], [-2, -1, -1]):
        with pytest.raises(InputError, match="pred_supported_by"):
            support(SUP_PRED, bad)


def test_cli_eval_reports_supported_by(tmp_path, capsys) -> None:
    d = tmp_path / "out"
    d.mkdir()
    np.savez(d / "labels.npz", surface=SUP_SURFACE, object=SUP_PRED)
    gt = tmp_path / "gt.npz"
    np.savez(gt, object=SUP_OBJECT, surface=SUP_SURFACE, supported_by=SUP_BY)
    objects = [{"id": i, "surface_id": 0, "supported_by": b} for i, b in enumerate([2, -1, -1])]
    (d / "result.json").write_text(json.dumps({"objects": objects}))
    out = tmp_path / "s.json"
    assert _main(["eval", str(d), str(gt), "--json", str(out)]) == 0
    assert "supported_by right  3/3 (stacked 1/1)" in capsys.readouterr().out
    assert json.loads(out.read_text())["objects"]["support"]["accuracy"] == 1.0
    # Results from before the field: the line says "-".
    for o in objects:
        del o["supported_by"]
    (d / "result.json").write_text(json.dumps({"objects": objects}))
    assert _main(["eval", str(d), str(gt)]) == 0
    assert "supported_by right  -" in capsys.readouterr().out
    objects[0]["supported_by"] = "table"
    for o in objects[1:]:
        o["supported_by"] = -1
    (d / "result.json").write_text(json.dumps({"objects": objects}))
    assert _main(["eval", str(d), str(gt)]) == 2
    err = capsys.readouterr().err
    assert "result.json: objects[0]" in err and err.count("\n") == 1


def test_cli_eval_organised_ply_truth_with_nan_rows(tmp_path, result_dir) -> None:
    """An organised cloud's NaN pixels are dropped on reading, as detect drops them; the
    labels (one per file row) still line up with the truth row by row."""
    clouds = pytest.importorskip("supportnode.io.clouds")
    points = np.random.default_rng(0).random((14, 3))
    points[[3, 10]] = np.nan  # two pixels without a return
    rows = np.delete(np.arange(14), [3, 10])
    obj, surf = np.full(14, -1, np.int32), np.full(14, -1, np.int32)
    obj[rows], surf[rows] = GT_OBJECT, GT_SURFACE
    gt = tmp_path / "organised.ply"
    clouds.write_ply(gt, points, fields={"object": obj, "surface": surf})
    np.savez(result_dir / "labels.npz", surface=surf, object=obj)
    out = tmp_path / "s.json"
    assert _main(["eval", str(result_dir), str(gt), "--json", str(out)]) == 0
    scores = json.loads(out.read_text())
    assert scores["points"] == 14 and scores["objects"]["ari"] == 1.0
    assert scores["surfaces"]["f1"] == 1.0
