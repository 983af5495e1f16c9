"""The type stub of boucwen._core matches the compiled module (mypy.stubtest), and the
installed package ships the stub and the py.typed marker."""

import importlib.util
import os
import subprocess
import sys
from importlib import resources
from pathlib import Path

import pytest

REPO_PYTHON = Path(__file__).resolve().parent.parent / "python"

# Only boucwen._core is checked: the package's other modules are followed silently
# (their own typing is not this test's business) and missing third-party stubs
# (scipy, matplotlib) are ignored.
MYPY_CONFIG = """\
[mypy]
ignore_missing_imports = True
follow_imports = silent

[mypy-boucwen._core]
follow_imports = normal
"""


def test_installed_package_ships_the_stub_and_py_typed():
    package = resources.files("boucwen")
    assert package.joinpath("_core.pyi").is_file()
    assert package.joinpath("py.typed").is_file()


@pytest.mark.skipif(importlib.util.find_spec("mypy") is None, reason="mypy is not installed (pip install mypy)")
def test_stub_matches_the_compiled_module(tmp_path):
    config = tmp_path / "mypy.ini"
    config.write_text(MYPY_CONFIG, encoding="utf-8")
    env = dict(os.environ)
    # Check the stub in the source tree when running from a checkout (the one being
    # edited), else the installed one; the runtime module is the installed extension.
    if (REPO_PYTHON / "boucwen" / "_core.pyi").is_file():
        env["MYPYPATH"] = str(REPO_PYTHON)
    result = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "boucwen._core", "--mypy-config-file", str(config)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
