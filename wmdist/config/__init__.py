"""Typed run configuration: schema, YAML loader with overlays and --set overrides, errors."""
from wmdist.config.errors import ConfigError
from wmdist.config.fields import param, section

__all__ = ["ConfigError", "param", "section", "load_config"]


def load_config(path, overrides=None):
    """See `wmdist.config.loader.load_config` (imported lazily: it pulls in every section)."""
    from wmdist.config.loader import load_config as _load

    return _load(path, overrides)
