"""On CI a skipped test fails the session (tests/conftest.py), elsewhere it does not."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CONFTEST = Path(__file__).with_name("conftest.py")
TESTS = {
    "skips": "import pytest\n\ndef test_ok():\n    pass\n\n"
             "def test_skipped():\n    pytest.skip('no EGL here')\n",
    "passes": "import pytest\n\ndef test_ok():\n    pass\n\n"
              "@pytest.mark.xfail(reason='known')\ndef test_xfail():\n    assert False\n",
    "module": "import pytest\n\npytest.importorskip('no_such_module_here')\n\n"
              "def test_ok():\n    pass\n",
}
PASSING = "def test_elsewhere():\n    pass\n"


def run(tmp_path: Path, kind: str, ci: bool | str) -> subprocess.CompletedProcess:
    """pytest on one tiny test file next to a copy of the project's conftest.py; ``ci``:
    True sets CI=1, a string sets CI to it, False leaves CI unset."""
    shutil.copy(CONFTEST, tmp_path / "conftest.py")
    (tmp_path / f"test_{kind}.py").write_text(TESTS[kind])
    (tmp_path / "test_passing.py").write_text(PASSING)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci is not False:
        env["CI"] = "1" if ci is True else ci
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           str(tmp_path)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("kind", ["skips", "module"])
def test_a_skip_fails_on_ci_and_names_the_test(tmp_path, kind):
    proc = run(tmp_path, kind, ci=True)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "skipped tests fail on CI" in proc.stdout
    if kind == "skips":
        assert "test_skips.py::test_skipped: no EGL here" in proc.stdout
    else:
        assert "test_module.py" in proc.stdout and "no_such_module_here" in proc.stdout


@pytest.mark.parametrize("kind", ["skips", "module"])
def test_a_skip_passes_off_ci(tmp_path, kind):
    proc = run(tmp_path, kind, ci=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "skipped tests fail on CI" not in proc.stdout


@pytest.mark.parametrize("value, on_ci", [("false", False), ("FALSE", False), ("0", False),
                                          ("no", False), ("", False), ("true", True),
                                          ("yes", True)])
def test_ci_is_any_value_but_false_ones(tmp_path, value, on_ci):
    proc = run(tmp_path, "skips", ci=value)
    assert proc.returncode == (1 if on_ci else 0), proc.stdout + proc.stderr
    assert ("skipped tests fail on CI" in proc.stdout) == on_ci


def test_no_skip_passes_on_ci(tmp_path):
    proc = run(tmp_path, "passes", ci=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed, 1 xfailed" in proc.stdout
