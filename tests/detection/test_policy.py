"""The safe rule: each threshold of the ``safe`` section decides on its own."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest

from supportnode.config import load_config
from supportnode.detection.policy import is_safe
from supportnode.errors import ConfigError
from supportnode.params import SafeParams


@dataclass
class _Surface:
    area: float = 0.5
    flatness: float = 0.004
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))


def _tilted(deg: float) -> np.ndarray:
    return np.array([math.sin(math.radians(deg)), 0.0, math.cos(math.radians(deg))])


def test_defaults_are_the_documented_rule() -> None:
    p = SafeParams()
    assert (p.min_area, p.max_flatness, p.max_tilt_deg) == (0.10, 0.01, 5.0)
    assert is_safe(_Surface(), p)
    assert not is_safe(_Surface(area=0.09), p)
    assert not is_safe(_Surface(flatness=0.011), p)
    assert is_safe(_Surface(normal=_tilted(4.9)), p)
    assert not is_safe(_Surface(normal=_tilted(5.1)), p)
    # a normal pointing down is the same plane
    assert is_safe(_Surface(normal=-_tilted(4.9)), p)
    assert not is_safe(_Surface(), p, hits=1, min_hits=2)
    assert is_safe(_Surface(), p, hits=2, min_hits=2)


def test_thresholds_come_from_the_config() -> None:
    params = load_config(None, ["safe.min_area=0.05", "safe.max_tilt_deg=10"]).safe
    assert is_safe(_Surface(area=0.06, normal=_tilted(8.0)), params)
    assert not is_safe(_Surface(area=0.06, normal=_tilted(8.0)), SafeParams())


def test_bad_safe_value_names_the_key() -> None:
    with pytest.raises(ConfigError, match=r"safe\.max_tilt_deg"):
        load_config(None, ["safe.max_tilt_deg=120"])
