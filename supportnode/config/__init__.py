"""Typed, strict configuration: built-in defaults < YAML file < ``--set key=value`` overrides.

The keys are the frozen dataclasses of `supportnode.params` (root `DetectParams`). Three modules:

- `schema`: the keys, their types, ranges and help as loading and dumping walk them, and the keys
  that were removed or renamed (`REMOVED_KEYS`, `RENAMED_KEYS`: reading one is an error naming
  the replacement);
- `load`: `load_config` and `parse_override`; every problem is one `ConfigError` line naming
  ``file:line`` (or the ``--set``) and the key, with a did-you-mean for a misspelt key;
- `dump`: `config_to_dict`, `dump_yaml` and `dump_default_yaml` (``config/default.yaml`` and
  ``supportnode config dump``).

Run ``python -m supportnode.config > config/default.yaml`` to regenerate the default file.
"""

from supportnode.config.dump import config_to_dict, dump_default_yaml, dump_yaml
from supportnode.config.load import load_config, parse_override
from supportnode.config.schema import REMOVED_KEYS, RENAMED_KEYS

__all__ = [
    "REMOVED_KEYS",
    "RENAMED_KEYS",
    "config_to_dict",
    "dump_default_yaml",
    "dump_yaml",
    "load_config",
    "parse_override",
]
