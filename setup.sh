#!/usr/bin/env bash
# Sets up rffqm-nlp on a fresh Debian machine with Python 3.11: system libraries for
# off-screen rendering (EGL and OSMesa) and Chromium for the browser test (when run as root
# with apt-get; the tests need them), then a virtual environment in .venv with the package and
# its test extra (which holds the viz and sweep extras). Safe to run again.
set -euo pipefail
cd "$(dirname "$0")"
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = "0" ]; then
    # chromium: the browser of tests/test_view_browser.py (Playwright drives it; never
    # `playwright install`); gcc: builds the shared library of tests/test_ipopt_options.py.
    if ! dpkg -s libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libxrender1 chromium gcc \
            libc6-dev >/dev/null 2>&1; then
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
            libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libxrender1 chromium gcc \
            libc6-dev >/dev/null
    fi
fi
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e ".[test]"
