"""``python -m supportnode.config > config/default.yaml``: print the default configuration."""

from supportnode.config.dump import dump_default_yaml

print(dump_default_yaml(), end="")
