"""Session settings: Hypothesis profiles, and on CI (environment variable CI set to anything
but "", "0", "false" or "no", in any case) a skipped test fails the session, so that a
missing library (EGL for rendering, an extra) cannot pass unnoticed."""

import os

import pytest
from hypothesis import settings

settings.register_profile("default", deadline=None, max_examples=40, derandomize=True)
settings.register_profile("ci", deadline=None, max_examples=40, derandomize=True,
                          print_blob=True)
ON_CI = os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")
settings.load_profile("ci" if ON_CI else "default")

#: (node id, reason) of every skipped test or module of this session
_SKIPPED: list[tuple[str, str]] = []


def _record(report) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        _SKIPPED.append((report.nodeid, reason.removeprefix("Skipped: ")))


def pytest_runtest_logreport(report) -> None:
    _record(report)


def pytest_collectreport(report) -> None:
    _record(report)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session, exitstatus) -> None:
    if ON_CI and _SKIPPED and exitstatus == 0:
        session.exitstatus = 1


def pytest_terminal_summary(terminalreporter) -> None:
    if ON_CI and _SKIPPED:
        terminalreporter.section("skipped tests fail on CI", sep="=", red=True, bold=True)
        for nodeid, reason in _SKIPPED:
            terminalreporter.line(f"SKIPPED {nodeid}: {reason}")
