"""Opens a run's report.html in headless Chromium (through Selenium and
Debian's chromedriver) as a reader would, and prints what the browser saw as
JSON: every image with its natural width (0: it did not load), the console's
messages (failed loads are logged there too), the page title and the text of
its tables; saves a screenshot of the whole page.

    python report_check.py REPORT.html SCREENSHOT.png
"""

import json
import pathlib
import shutil
import sys

from selenium import webdriver
from selenium.webdriver.chrome.service import Service


def browser(width):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not chromium or not driver:
        sys.exit("chromium and chromedriver are needed (Debian: apt-get install chromium chromium-driver)")
    opts = webdriver.ChromeOptions()
    for a in ["--headless=new", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
              f"--window-size={width},1000"]:
        opts.add_argument(a)
    opts.binary_location = chromium
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver), options=opts)


def main():
    page, shot = pathlib.Path(sys.argv[1]).resolve(), sys.argv[2]
    width = 1280
    d = browser(width)
    try:
        d.get(page.as_uri())
        d.execute_script("return document.readyState")
        seen = d.execute_script(
            "return {title: document.title,"
            " images: Array.from(document.images).map(i => ({src: i.getAttribute('src'),"
            "   complete: i.complete, width: i.naturalWidth})),"
            " tables: Array.from(document.querySelectorAll('table')).map(t => t.innerText),"
            " height: document.documentElement.scrollHeight}")
        seen["console"] = d.get_log("browser")
        # the whole page in one picture
        d.set_window_size(width, min(int(seen["height"]) + 100, 12000))
        d.save_screenshot(shot)
    finally:
        d.quit()
    print(json.dumps(seen))


main()
