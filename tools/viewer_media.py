#!/usr/bin/env python3
"""The README's viewer pictures, taken from the real page in headless chromium (tools/browser.py):

    python tools/viewer_media.py [--out docs/figures] [--n 128] [--size 256] [--steps 24]

``viewer_page.png``: a screenshot of the page (hydrogen, scalar, shaded through its preset at render time);
``viewer_orbit.gif``: the image as the page shows it after each of ``--steps`` drags that orbit once around
the Shepp-Logan phantom (X-ray; each frame the refined one of its view).
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

import browser  # noqa: E402  (tools/browser.py)
import clwave  # noqa: E402
from clwave.view import view  # noqa: E402

#: degrees of azimuth per pixel dragged (clwave/view/static/controls.js)
DEGREES_PER_PIXEL = 0.4


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument("--n", type=int, default=128, help="phantom voxels per axis")
    parser.add_argument("--size", type=int, default=256, help="the viewer's image size")
    parser.add_argument("--steps", type=int, default=24, help="drags around the orbit (frames of the GIF)")
    args = parser.parse_args(argv)
    import imageio.v3 as iio

    frames = []
    with view(clwave.phantom("shepp-logan", n=args.n), size=args.size, keep=0.05) as viewer, \
            browser.chromium(width=args.size + 340, height=args.size + 300) as driver:
        browser.open_viewer(driver, viewer.url)
        browser.wait_final(driver)
        canvas = driver.find_element("id", "image")
        step = 360.0 / args.steps / DEGREES_PER_PIXEL
        for _ in range(args.steps):
            browser.drag(driver, -step, 0, steps=3, pause=0.02, hold=False)
            browser.wait_final(driver)
            frames.append(iio.imread(io.BytesIO(canvas.screenshot_as_png))[..., :3])
    with view(clwave.phantom("hydrogen", n=args.n), size=args.size, keep=0.05) as viewer, \
            browser.chromium(width=args.size + 340, height=1000) as driver:
        browser.open_viewer(driver, viewer.url)
        driver.execute_script('document.querySelector(\'input[value="shaded"]\').click();'
                              'const p = document.getElementById("tf-preset"); p.value = "hydrogen";'
                              'p.dispatchEvent(new Event("change"));')
        browser.drag(driver, 20, 40, steps=3, pause=0.02, hold=False)
        browser.wait_final(driver, timeout=600)
        page = driver.get_screenshot_as_png()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "viewer_page.png").write_bytes(page)
    iio.imwrite(args.out / "viewer_orbit.gif", np.stack(frames), extension=".gif", duration=120, loop=0)
    print(f"wrote {args.out / 'viewer_page.png'} and {args.out / 'viewer_orbit.gif'} ({len(frames)} frames)")


if __name__ == "__main__":
    main()
