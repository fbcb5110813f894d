"""Shared test set-up."""

import warnings

with warnings.catch_warnings():
    # pyAgrum's SWIG module emits DeprecationWarnings while it loads and crashes the interpreter
    # when they are errors (pytest runs with warnings as errors); pgmpy warns about its own
    # deprecated modules. Import both once, quietly, before any test module does.
    warnings.simplefilter("ignore")
    import pgmpy.inference  # noqa: F401
    import pyagrum  # noqa: F401

import os  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

# checked programs are kept in a folder of the test run's own, not in the user's cache (the
# processes the tests start inherit it, the parallel workers too); the process that made it
# removes it when it ends
if "BAYESPROG_CACHE" not in os.environ:
    import atexit  # noqa: E402
    import tempfile  # noqa: E402

    os.environ["BAYESPROG_CACHE"] = tempfile.mkdtemp(prefix="bayesprog-test-cache-")
    atexit.register(shutil.rmtree, os.environ["BAYESPROG_CACHE"], ignore_errors=True)

# the tests stop the commands they start with Ctrl-C as a terminal would; a test run started in
# the background by a shell, which ignores Ctrl-C there, would pass that on to them
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture
def screenshot(tmp_path):
    """``screenshot(page, width, height) -> RGB array [h, w, 3]`` of an HTML file rendered by
    headless Chromium. Skipped where no browser is installed, unless BAYESPROG_REQUIRE_BROWSER
    is set (CI installs Debian's chromium and sets it)."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        if os.environ.get("BAYESPROG_REQUIRE_BROWSER"):
            pytest.fail("BAYESPROG_REQUIRE_BROWSER is set but no chromium is installed")
        pytest.skip("no chromium here (CI installs it and requires the browser tests)")

    def take(page: Path, width: int = 1000, height: int = 800) -> np.ndarray:
        import matplotlib.image

        shot = tmp_path / f"{page.stem}.png"
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                        "--no-first-run", "--disable-background-networking",
                        "--disable-component-update", "--disable-sync", "--hide-scrollbars",
                        f"--user-data-dir={tmp_path / 'profile'}",
                        f"--window-size={width},{height}", f"--screenshot={shot}",
                        page.as_uri()], capture_output=True, timeout=120, check=True)
        return matplotlib.image.imread(shot)[..., :3]

    return take
