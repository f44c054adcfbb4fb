"""Drive the viewer's page in Debian's headless Chromium (Selenium with the system chromedriver; nothing is
downloaded).  Used by tests/test_view_browser.py, ``tools/bench.py view`` and tools/viewer_media.py.

``bash tools/setup.sh --test`` installs ``chromium`` and ``chromium-driver``.
"""

from __future__ import annotations

import base64
import shutil
import time
from contextlib import contextmanager

SETUP = "install Debian's chromium and chromium-driver (bash tools/setup.sh --test does)"


def executables() -> tuple:
    """``(browser, driver)`` paths, or None where either is missing."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


@contextmanager
def chromium(width=1100, height=760):
    """A headless Chromium (a Selenium driver) with a window of ``width`` x ``height``."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    found = executables()
    if found is None:
        raise RuntimeError(f"no chromium with chromedriver here: {SETUP}")
    options = webdriver.ChromeOptions()
    options.binary_location = found[0]
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={width},{height}", "--disable-background-timer-throttling",
                "--disable-renderer-backgrounding", "--disable-backgrounding-occluded-windows"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(found[1]), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def wait_for(driver, script, timeout=60.0, poll=0.01):
    """Poll the JavaScript expression ``script`` (``return ...``) until it is truthy; its value."""
    end = time.perf_counter() + timeout
    while True:
        value = driver.execute_script(script)
        if value:
            return value
        if time.perf_counter() > end:
            raise TimeoutError(f"the page did not reach `{script}` within {timeout} s")
        time.sleep(poll)


def open_viewer(driver, url, timeout=60.0) -> float:
    """Load the page and wait for its first image; the seconds from the page's start to that image."""
    driver.get(url)
    return wait_for(driver, "return window.clwave && window.clwave.stats.firstImage", timeout) / 1000.0


def shown(driver) -> int:
    return driver.execute_script("return window.clwave.stats.shown")


def wait_final(driver, timeout=60.0) -> dict:
    """Wait until the page shows the final frame of its latest view; that frame's figures."""
    return wait_for(driver, "const c = window.clwave.current(); return !window.clwave.state.moving && c && "
                            "c.fig.final && c.fig.seq === window.clwave.latest() && c.fig", timeout)


def drag(driver, dx, dy, steps=10, pause=0.03, hold=True, start=(0, 0)):
    """Press on the image ``start`` pixels from its centre, move by ``(dx, dy)`` pixels in ``steps`` moves ``pause``
    seconds apart, and release (unless ``hold``: then :func:`release` ends it)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    image = driver.find_element(By.ID, "image")
    chain = ActionChains(driver, duration=0).move_to_element_with_offset(image, *start).click_and_hold()
    for _ in range(steps):
        chain.move_by_offset(round(dx / steps), round(dy / steps)).pause(pause)
    if not hold:
        chain.release()
    chain.perform()


def release(driver):
    from selenium.webdriver.common.action_chains import ActionChains
    ActionChains(driver, duration=0).release().perform()


def current_frame(driver) -> tuple:
    """``(figures, encoded picture)`` of the frame the page shows."""
    figures, url = driver.execute_async_script(
        "const done = arguments[arguments.length - 1], c = window.clwave.current();"
        "const r = new FileReader(); r.onload = () => done([c.fig, r.result]); r.readAsDataURL(c.blob);")
    return figures, base64.b64decode(url.split(",", 1)[1])
