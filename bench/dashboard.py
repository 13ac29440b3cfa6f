"""The dashboard's cost: the viewer's frame time in headless Chromium, and the display endpoint on a 10^6-particle
result.

Starts its own ``redis-server`` and a real ``hairport serve`` on a temporary storage holding one succeeded job
whose result is a procedural long groom of ``--particles`` particles (``--particles-per-strand`` each) on the
MakeHuman average female (its scene written as a job's run writes it, without solving: the figures are of
drawing and shipping, not of retargeting). Then:

* ``GET /v1/jobs/{id}/display``: the first request (the scene read from storage) and the median of ``--runs``
  more (the scene kept by the API process), at the default budget and other plans, next to two baselines
  measured in the same run: every particle through the display endpoint, and the lossless result download
  (``GET /v1/jobs/{id}/result?format=npz``) that a client would otherwise decimate itself;
* the viewer page (``/ui/#/view/{id}?budget=N``) in Debian's Chromium with software WebGL (SwiftShader: no GPU
  here), at each ``--vertices`` budget: the time from navigation to the first drawn frame, and the median
  frame time over ``--frames`` frames drawn back to back with the camera turning (each frame waited for by a
  pixel read), median over ``--runs`` page loads.

    python bench/dashboard.py [--particles 1000000] [--vertices 10000 100000 1000000] [--runs 5]

Prints tables; not a test.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]

from service_load import KEY, Service, wait_until  # noqa: E402

from tests.integration.browser import ARGS, chromium_path  # noqa: E402

HEADERS = {"X-API-Key": KEY}
#: a frame at or under this many milliseconds keeps the viewer at 30 frames per second
SMOOTH_FRAME_MS = 1000 / 30


def seed_job(storage: Path, particles: int, per_strand: int, folder: Path) -> str:
    """A succeeded job of the bench key whose outputs are a scene and a lossless result."""
    from hairport import solver
    from hairport.records import BlobRef, JobRecord, PreprocessSettings, now
    from hairport.repository import Repository
    from hairport.service.auth import owner_of
    from hairport.solver import display
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character
    from hairport.storage import LocalStorage

    body = build_character(PRESETS["average-female"])
    groom = generate_groom(body, "long", particles // per_strand, per_strand, seed=0)
    hairline = {"points": [[0.07, 1.6, 0.05], [0.0, 1.65, 0.1], [-0.07, 1.6, 0.05]], "turning_points": [0, 2]}
    scene = display.scene_arrays(groom.points, groom.offsets, np.zeros(groom.n_particles, bool), None, body.vertices,
                                body.faces, np.eye(3), hairline, {})
    display.save_scene(folder / "scene.npz", scene)
    solver.write_hair(folder / "result.npz", groom, format="npz")
    repository = Repository(LocalStorage(storage))
    outputs = {}
    for name, file in (("scene", "scene.npz"), ("npz", "result.npz")):
        blob = repository.storage.save_file(folder / file, ".npz")
        outputs[name] = BlobRef(sha256=blob.sha256, suffix=".npz", size=blob.size)
    job = JobRecord(id="d" * 32, owner=owner_of(KEY), hairstyle_id="0" * 32, target_character_id="0" * 32,
                    options={"method": "multiscale"}, preprocess_options=PreprocessSettings(k=5, guides=20),
                    artifact_key="0" * 64, output_format="npz", created_at=now(), updated_at=now(), state="succeeded",
                    outputs=outputs, finished_at=now())
    repository.create_job(job)
    return job.id


def endpoint_rows(url: str, job_id: str, runs: int) -> list[tuple]:
    """(what, first s, median s, MB) per request, in order (the first display request reads the scene)."""
    plans = [("display, default budget", f"/v1/jobs/{job_id}/display", {}),
             ("display, 10^4 vertices", f"/v1/jobs/{job_id}/display", {"max_vertices": 10_000}),
             ("display, 10^5 vertices", f"/v1/jobs/{job_id}/display", {"max_vertices": 100_000}),
             ("display, 2000 strands stride 4", f"/v1/jobs/{job_id}/display", {"strands": 2000, "stride": 4}),
             ("baseline: display of every particle", f"/v1/jobs/{job_id}/display", {"max_vertices": 2_000_000}),
             ("baseline: lossless result download", f"/v1/jobs/{job_id}/result", {"format": "npz"})]
    rows = []
    with httpx.Client(base_url=url, headers=HEADERS, timeout=120) as client:
        for what, path, params in plans:
            times = []
            for _ in range(runs + 1):
                began = time.perf_counter()
                response = client.get(path, params=params)
                times.append(time.perf_counter() - began)
                response.raise_for_status()
            rows.append((what, times[0], statistics.median(times[1:]), len(response.content) / 1e6))
    return rows


def viewer_rows(url: str, job_id: str, budgets: list[int], frames: int, runs: int) -> list[tuple]:
    """(budget, drawn vertices, first frame s, median frame ms, frames per second) per budget, and the body alone
    (measured with the first budget's page)."""
    from playwright.sync_api import sync_playwright

    rows = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium_path(), args=list(ARGS))
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.goto(f"{url}/ui/")
        page.evaluate(f"() => sessionStorage.setItem('hairport.apiKey', '{KEY}')")
        for budget in budgets:
            loads, frame_ms, body_ms, drawn = [], [], [], 0
            for _ in range(runs):
                page.goto(f"{url}/ui/#/jobs")
                began = time.perf_counter()
                page.goto(f"{url}/ui/#/view/{job_id}?budget={budget}")
                page.wait_for_selector("#viewer[data-loaded=true]", timeout=300_000)
                loads.append(time.perf_counter() - began)
                times = page.evaluate(f"() => window.hairportViewer.measureFrames({frames + 3})")[3:]
                frame_ms.append(statistics.median(times))
                if budget == budgets[0]:  # the body alone, the floor every budget pays
                    page.evaluate("() => window.hairportViewer.visible('result', false)")
                    body_ms.append(statistics.median(
                        page.evaluate(f"() => window.hairportViewer.measureFrames({frames + 3})")[3:]))
                drawn = int(page.get_attribute("#viewer", "data-vertices") or 0)
            if body_ms:
                body = statistics.median(body_ms)
                rows.append(("body alone", 0, float("nan"), body, 1000 / body))
            median_ms = statistics.median(frame_ms)
            rows.append((budget, drawn, statistics.median(loads), median_ms, 1000 / median_ms))
        browser.close()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=1_000_000)
    parser.add_argument("--particles-per-strand", type=int, default=50)
    parser.add_argument("--vertices", type=int, nargs="+", default=[10_000, 50_000, 100_000, 200_000, 1_000_000])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="hairport-bench-dashboard-") as scratch:
        folder = Path(scratch)
        service = Service(folder, {}, [])
        try:
            service.start_redis()
            job_id = seed_job(service.storage, args.particles, args.particles_per_strand, folder)
            service._spawn("serve", [sys.executable, "-m", "hairport.cli", "serve", "--port", str(service.port)])
            wait_until(lambda: httpx.get(f"{service.url}/healthz", timeout=5).status_code == 200, "the API")
            endpoint = endpoint_rows(service.url, job_id, args.runs)
            viewer = viewer_rows(service.url, job_id, args.vertices, args.frames, args.runs)
        finally:
            service.stop()
    print(f"# bench/dashboard.py, {date.today()}, {platform.machine()}, {platform.processor() or 'cpu'}; "
          f"a result of {args.particles:,} particles ({args.particles_per_strand} per strand); "
          f"median of {args.runs} runs")
    print("\n| request | first s | median s | MB |\n|---|---|---|---|")
    for what, first, median, megabytes in endpoint:
        print(f"| {what} | {first:.3f} | {median:.3f} | {megabytes:.1f} |")
    print("\nChromium with software WebGL (SwiftShader, no GPU: the viewer draws without antialiasing), 1280 x 900 "
          "window:")
    print("\n| budget | vertices drawn | navigation to first frame s | frame ms | frames/s |\n|---|---|---|---|---|")
    for budget, drawn, load, frame, fps in viewer:
        label = budget if isinstance(budget, str) else f"{budget:,}"
        print(f"| {label} | {drawn:,} | {load:.2f} | {frame:.1f} | {fps:.1f}{'' if frame <= SMOOTH_FRAME_MS else ' (under 30)'} |")


if __name__ == "__main__":
    main()
