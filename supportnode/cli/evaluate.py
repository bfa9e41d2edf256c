"""`supportnode eval RESULT_DIR GT_CLOUD [--json OUT]`: score a detect output against ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

GT_KEYS = ("role", "primitive", "object", "surface")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the eval subcommand."""
    parser.add_argument("result_dir", type=Path, help="output folder of `supportnode detect`")
    parser.add_argument(
        "gt_cloud",
        type=Path,
        help="ground truth: .npz with role/primitive/object/surface, or a .ply with them",
    )
    parser.add_argument("--json", type=Path, default=None, metavar="OUT", help="write scores")


def _load_labels(result_dir: Path) -> dict[str, Any]:
    import numpy as np

    from supportnode.errors import SupportNodeError

    path = result_dir / "labels.npz"
    if not path.is_file():
        raise SupportNodeError(f"{path}: no labels.npz (is {result_dir} a detect output?)")
    try:
        with np.load(path) as z:
            missing = [k for k in ("surface", "object") if k not in z.files]
            if missing:
                raise SupportNodeError(f"{path}: missing arrays {', '.join(missing)}")
            labels = {"surface": z["surface"], "object": z["object"], "path": path}
    except (OSError, ValueError) as err:
        raise SupportNodeError(f"{path}: cannot read: {err}") from err
    labels["supported_by"] = _load_supported_by(result_dir / "result.json")
    return labels


def _load_supported_by(path: Path) -> Any:
    """(C,) supported_by per object from result.json, or None without the file or the field."""
    import json

    from supportnode.errors import InputError, SupportNodeError
    from supportnode.sim.evaluate import supported_by_of

    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
        return supported_by_of(doc.get("objects", []) if isinstance(doc, dict) else [])
    except (OSError, ValueError) as err:
        raise SupportNodeError(f"{path}: cannot read: {err}") from err
    except InputError as err:
        raise SupportNodeError(f"{path}: {err}") from err


def _load_truth(path: Path) -> dict[str, Any]:
    import numpy as np

    from supportnode.errors import SupportNodeError

    if not path.is_file():
        raise SupportNodeError(f"{path}: no such file")
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path) as z:
                fields = {k: z[k] for k in z.files}
        except (OSError, ValueError) as err:
            raise SupportNodeError(f"{path}: cannot read: {err}") from err
    else:
        from supportnode.io.clouds import read_cloud

        cloud = read_cloud(path)
        # Rows without a finite point (an organised cloud's NaN pixels) are dropped on reading,
        # as detect drops them; their truth is "none", so the labels line up row by row.
        fields = {}
        for key, value in cloud.fields.items():
            full = np.full((cloud.input_count, *value.shape[1:]), -1, value.dtype)
            full[cloud.source_index] = value
            fields[key] = full
    missing = [k for k in ("object", "surface") if k not in fields]
    if missing:
        raise SupportNodeError(
            f"{path}: no ground truth {', '.join(missing)} (expected fields {', '.join(GT_KEYS)})"
        )
    return fields


def run(args: argparse.Namespace) -> int:
    """Load, score, print a short table, optionally write JSON; 0 on success."""
    import json

    import numpy as np

    from supportnode.errors import SupportNodeError
    from supportnode.sim.evaluate import evaluate, format_support

    labels = _load_labels(args.result_dir)
    truth = _load_truth(args.gt_cloud)
    n_pred, n_gt = labels["surface"].shape[0], truth["surface"].shape[0]
    if n_pred != n_gt or labels["object"].shape[0] != n_pred or truth["object"].shape[0] != n_gt:
        raise SupportNodeError(
            f"{labels['path']} has {n_pred} labels but {args.gt_cloud} has {n_gt} points: "
            "not the same cloud"
        )
    scores = evaluate(
        labels["surface"].astype(np.int64),
        labels["object"].astype(np.int64),
        np.asarray(truth["surface"]).astype(np.int64),
        np.asarray(truth["object"]).astype(np.int64),
        None if "supported_by" not in truth else np.asarray(truth["supported_by"]).astype(np.int64),
        labels["supported_by"],
    )
    s, o = scores["surfaces"], scores["objects"]
    rows = [
        ("points", f"{scores['points']}"),
        ("surface precision", f"{s['precision']:.3f}"),
        ("surface recall", f"{s['recall']:.3f}"),
        ("surface F1", f"{s['f1']:.3f}"),
        ("surfaces found", f"{s['found']} of {s['gt_count']} (mean IoU {s['mean_iou']:.3f})"),
        ("spurious surfaces", f"{s['spurious']}"),
        ("object ARI", f"{o['ari']:.3f}"),
        ("objects found", f"{o['found']} of {o['gt_count']}"),
        ("objects merged", f"{o['merged']} {o['merged_groups'] or ''}".rstrip()),
        ("objects split", f"{o['split']}"),
        ("supported_by right", format_support(o["support"])),
    ]
    from supportnode.cli._console import print_table

    print_table(("score", "value"), rows, left=2)
    if args.json is not None:
        scores["result_dir"] = str(args.result_dir)
        scores["gt_cloud"] = str(args.gt_cloud)
        try:
            args.json.write_text(json.dumps(scores, indent=2) + "\n")
        except OSError as err:
            raise SupportNodeError(f"{args.json}: cannot write: {err}") from err
    return 0
