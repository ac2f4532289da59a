"""Shared fixtures: a headless Chromium (Debian's chromium + chromium-driver, driven by Selenium).

The tests mirror the package (``tests/<package>/test_*.py``); the helpers several packages' tests share
(``doctor_cases``, ``simd_asm``) stay here, importable from every folder."""
import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


def _browser_or_skip():
    why = None
    if not os.path.exists(CHROMIUM):
        why = f"{CHROMIUM} missing (Debian package 'chromium'; .ci/run installs it)"
    elif not os.path.exists(CHROMEDRIVER):
        why = f"{CHROMEDRIVER} missing (Debian package 'chromium-driver'; .ci/run installs it)"
    else:
        try:
            import selenium  # noqa: F401
        except ImportError:
            why = "selenium not installed (pip install -e '.[test]')"
    if why is not None:
        if os.environ.get("STUDY_REQUIRE_BROWSER") == "1":
            pytest.fail(f"STUDY_REQUIRE_BROWSER=1 but {why}")
        pytest.skip(why)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    _browser_or_skip()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    old = os.environ.get("SE_OFFLINE")
    os.environ["SE_OFFLINE"] = "true"  # Selenium Manager must never try to download a driver
    profile = tmp_path_factory.mktemp("chromium-profile")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--no-first-run", "--disable-extensions", "--window-size=1280,900",
                 f"--user-data-dir={profile}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()
        if old is None:
            os.environ.pop("SE_OFFLINE", None)
        else:
            os.environ["SE_OFFLINE"] = old


