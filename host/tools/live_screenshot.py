"""A PNG of the live view (docs/live.md) as headless Chromium draws it.

    .venv/bin/python host/tools/live_screenshot.py http://127.0.0.1:8765/ live.png --points 100

Waits until the page reports at least --points rows of the current position
(its #points[data-points]) while that position runs, then saves the page. Selenium drives the
system's Chromium (apt: chromium chromium-driver) through the chromedriver
named here, so Selenium Manager never goes to the network. The browser
test (host/tests/test_live_browser.py) opens its browser with ``chromium``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

CHROMIUM = os.environ.get("THERMOTILT_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("THERMOTILT_CHROMEDRIVER", "/usr/bin/chromedriver")
WINDOW = (1400, 1250)


@contextmanager
def chromium(window: tuple[int, int] = WINDOW) -> Iterator[webdriver.Chrome]:
    """Headless Chromium; --no-sandbox because CI runs as root."""
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu"):
        options.add_argument(argument)
    options.add_argument(f"--window-size={window[0]},{window[1]}")
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def points(driver: webdriver.Chrome) -> int:
    """The rows of the current position the page has drawn."""
    return int(driver.find_element(By.ID, "points").get_attribute("data-points") or 0)


def running(driver: webdriver.Chrome) -> bool:
    return driver.find_element(By.ID, "position").get_attribute("data-status") == "running"


def take(
    url: str,
    path: Path | str,
    wait_for_points: int = 1,
    timeout_s: float = 30.0,
    stop_waiting: Callable[[], bool] = lambda: False,
) -> bool:
    """Opens url, waits for wait_for_points rows drawn of a running
    position, saves a PNG at path; False when stop_waiting said so first
    (the page is saved as it is then)."""
    path = Path(path)
    with chromium() as driver:
        driver.get(url)
        WebDriverWait(driver, timeout_s).until(
            lambda d: (running(d) and points(d) >= wait_for_points) or stop_waiting()
        )
        caught = running(driver) and points(driver) >= wait_for_points
        # The whole page: the window grown until its viewport holds it (the
        # window's height counts the browser's own bars too).
        for _ in range(3):
            missing = driver.execute_script("return document.documentElement.scrollHeight - window.innerHeight")
            if missing <= 0:
                break
            driver.set_window_size(WINDOW[0], driver.get_window_size()["height"] + int(missing) + 16)
            time.sleep(0.5)
        driver.save_screenshot(str(path))
    return caught


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", help="the live view, e.g. http://127.0.0.1:8765/")
    parser.add_argument("png", help="where to save the screenshot")
    parser.add_argument("--points", type=int, default=1, help="wait for this many rows drawn (default 1)")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for them (default 30)")
    args = parser.parse_args()
    take(args.url, args.png, args.points, args.timeout)
    print(args.png)


if __name__ == "__main__":
    main()
