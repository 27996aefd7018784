"""Names of a package loaded on first use (PEP 562), so that importing `pipeline` or `pipeline.io`
costs nothing until a caller asks for something that needs numpy, rosbags or MuJoCo."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_attributes(package: str, table: Mapping[str, str]) -> Callable[[str], Any]:
    """A module `__getattr__` for `package`: `table[name]` names where `name` lives, as `module`
    or `module:attribute` where the public name is another."""

    def load(name: str) -> Any:
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, _, attribute = table[name].partition(":")
        return getattr(importlib.import_module(module), attribute or name)

    return load
