"""Where the shipped examples are: launch files, configurations, the demo's recording.

A wheel installs them as data files under ``<prefix>/share/supportnode/`` (``launch/``,
``config/``, ``examples/``, ``sim_scans/``, laid out as in the repository, so the launch files'
relative paths hold); a source checkout uses the repository itself.
"""

from __future__ import annotations

import site
import sys
import sysconfig
from pathlib import Path

from supportnode.errors import SupportNodeError

__all__ = ["find_shipped", "share_dir"]

_MARKER = Path("launch") / "demo.yaml"


def share_dir() -> Path:
    """The folder holding ``launch/``, ``config/``, ``examples/`` and ``sim_scans/``."""
    repo = Path(__file__).resolve().parents[1]
    candidates = [
        repo,
        Path(sysconfig.get_path("data")) / "share" / "supportnode",
        Path(site.getuserbase()) / "share" / "supportnode",
        Path(sys.prefix) / "share" / "supportnode",
    ]
    for folder in candidates:
        if (folder / _MARKER).is_file():
            return folder
    raise SupportNodeError(
        "the shipped examples are missing (looked in "
        + ", ".join(str(c) for c in candidates[1:])
        + "): reinstall supportnode"
    )


def find_shipped(kind: str, name: str) -> Path:
    """A shipped file by short name: ``find_shipped("launch", "demo")`` -> .../launch/demo.yaml.

    Raises SupportNodeError listing the names there are when ``name`` is not one of them."""
    folder = share_dir() / kind
    path = folder / (name if name.endswith(".yaml") else f"{name}.yaml")
    if path.is_file():
        return path
    names = sorted(p.stem for p in folder.glob("*.yaml"))
    raise SupportNodeError(f"no shipped {kind} file {name!r} (there are: {', '.join(names)})")
