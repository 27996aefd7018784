"""`pipeline`'s and `pipeline.io`'s public API: every name in `__all__` resolves (the lazy tables
cannot point at a module or name that moved), and importing either package loads no numpy."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

PUBLIC_PACKAGES = ("pipeline", "pipeline.io")


@pytest.mark.parametrize("package", PUBLIC_PACKAGES)
def test_every_public_name_resolves(package: str) -> None:
    module = importlib.import_module(package)
    missing = [name for name in module.__all__ if getattr(module, name, None) is None]
    assert missing == []


@pytest.mark.parametrize("package", PUBLIC_PACKAGES)
def test_the_lazy_table_holds_only_public_names(package: str) -> None:
    module = importlib.import_module(package)
    assert set(module._LAZY) <= set(module.__all__)
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        module.not_a_name  # noqa: B018


@pytest.mark.parametrize("package", PUBLIC_PACKAGES)
def test_importing_loads_no_numpy(package: str) -> None:
    probe = f"import sys, {package}; print('numpy' in sys.modules, 'rosbags' in sys.modules)"
    done = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parents[2],
        timeout=60,
        check=True,
    )
    assert done.stdout.split() == ["False", "False"]


@pytest.mark.parametrize("package", PUBLIC_PACKAGES)
def test_no_public_name_is_also_a_submodule(package: str) -> None:
    # `from pipeline import calibrate` would give the module `pipeline.calibrate` once it is
    # loaded (the import system sets it on the package), not the lazily loaded function.
    module = importlib.import_module(package)
    folder = Path(module.__file__ or "").parent
    submodules = {path.stem for path in folder.glob("*.py")} | {
        path.parent.name for path in folder.glob("*/__init__.py")
    }
    assert set(module.__all__) & submodules == set()
