"""The dashboard end to end in a real browser (Debian's Chromium, software WebGL) against real processes: a
``hairport serve``, a ``hairport worker`` and the tests' own Redis. Every step's screenshot is kept under
``test-artifacts/dashboard/``."""

from __future__ import annotations

import math
import re
import time

import httpx
import numpy as np
import pytest

from hairport.solver.display import decode
from hairport.solver.model.frame import InputFrame
from tests.conftest import free_port
from tests.integration.browser import (
    ARTIFACTS,
    chromium,
    count_drawn,
    count_near,
    count_red,
    mean_column_near,
    pixels,
    rows_near,
)
from tests.integration.deployment import KEY, service_env, spawn_server, spawn_worker, stop, wait_ready
from tests.solver.frames import character_in, faces_only, hair_in, head_faces

SHOTS = ARTIFACTS / "dashboard"
#: seconds the server and its worker may take to be ready (the worker compiles or loads the solver's kernels)
READY_SECONDS = 120
#: seconds a small MakeHuman retarget, or a batch of two, may take here
JOB_SECONDS = 300
GROOM_STRANDS, GROOM_PARTICLES = 300, 20
SOURCE, HEAVY = "average-female", "heavy-male"
#: the viewer's colours of result and source strands (dashboard/src/scene.js LAYER_RGB)
RESULT_RGB = (112, 74, 38)
SOURCE_RGB = (70, 110, 170)
#: the foreign heads' frame and cut (m below the head joint)
FOREIGN_FRAME = InputFrame("mm", "z", "-y")
HEAD_CUT_M = 0.10


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Two MakeHuman characters (OBJ + skeleton JSON) and a groom made on the first (npz)."""
    from hairport.solver.io.character.export import write_character
    from hairport.solver.io.character.obj import write_obj
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    folder = tmp_path_factory.mktemp("dashboard-inputs")
    characters = {name: build_character(PRESETS[name]) for name in (SOURCE, HEAVY)}
    for name, character in characters.items():
        write_character(character, folder / f"{name}.obj", folder / f"{name}.json")
    write_hair(folder / "groom.npz", generate_groom(characters[SOURCE], "long", GROOM_STRANDS, GROOM_PARTICLES, seed=3))
    (folder / "notes.txt").write_text("not a mesh\n")
    # the same heads as a DCC tool might export them: millimetres, Z up, no rig, cut open at the neck,
    # and a fringe in a format that records no units
    keep = head_faces(characters[SOURCE], HEAD_CUT_M)
    for name, character in characters.items():
        head = character_in(FOREIGN_FRAME, faces_only(character, keep, name))
        write_obj(folder / f"{name}-head-mm.obj", head.vertices, head.faces, "a head in mm, Z up, no rig")
    head = faces_only(characters[HEAVY], keep, HEAVY)
    write_obj(folder / f"{HEAVY}-head.obj", head.vertices, head.faces, "the same head in hairport's frame")
    fringe = generate_groom(characters[SOURCE], "fringe", GROOM_STRANDS, GROOM_PARTICLES, seed=4)
    write_hair(folder / "fringe-mm.data", hair_in(FOREIGN_FRAME, fringe))
    return folder


@pytest.fixture(scope="module")
def deployment(tmp_path_factory, redis_url):
    """A real server on a free port and one worker, sharing a storage folder and the tests' Redis."""
    storage = tmp_path_factory.mktemp("dashboard-storage")
    env = service_env(storage, redis_url)
    port = free_port()
    server = spawn_server(env, port, storage)
    worker = spawn_worker("dashboard", env, storage)
    base = f"http://127.0.0.1:{port}"
    try:
        wait_ready(base, server, worker, storage, "dashboard", READY_SECONDS)
        yield {"base": base, "api": httpx.Client(base_url=base, headers={"X-API-Key": KEY}, timeout=30)}
    finally:
        stop(worker)
        stop(server)


def shot(page, name: str, selector: str | None = None) -> bytes:
    SHOTS.mkdir(parents=True, exist_ok=True)
    target = page.locator(selector) if selector else page
    return target.screenshot(path=str(SHOTS / f"{name}.png"))


def enter_key(page, base: str, key: str) -> None:
    page.goto(f"{base}/")
    page.fill("#api-key", key)
    page.click("#key-form button")


def wait_job(api: httpx.Client, job_id: str) -> dict:
    deadline = time.monotonic() + JOB_SECONDS
    while True:
        job = api.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in ("succeeded", "failed", "cancelled"):
            return job
        assert time.monotonic() < deadline, f"job {job_id} still {job['state']}"
        time.sleep(0.5)


def viewer_pixels(page, name: str) -> np.ndarray:
    page.wait_for_timeout(400)  # the viewer draws on the next animation frame
    return pixels(shot(page, name, "#viewer"))


def upload_character(page, mesh, skeleton=None, up_axis: str = "auto") -> str:
    """A character through the open characters page's form: its id, from the page's message."""
    page.wait_for_selector("#character-form")
    page.set_input_files("input[name=mesh]", str(mesh))
    if skeleton is not None:
        page.set_input_files("input[name=skeleton]", str(skeleton))
    page.select_option("#character-form select[name=up_axis]", up_axis)
    page.click("#character-form button[type=submit]")
    message = page.wait_for_selector("#message.info:has-text('stored')")
    page.evaluate("() => { document.querySelector('#message').className = 'stale'; }")  # the next one waits anew
    return re.search(r"character ([0-9a-f]+) stored", message.inner_text()).group(1)


def upload_hairstyle(page, base: str, hair, source_id: str) -> str:
    """A groom through the hairstyles page, waited for until preprocessed: its id."""
    page.goto(f"{base}/ui/#/hairstyles")
    page.wait_for_selector("#hairstyle-form")
    page.set_input_files("input[name=hair]", str(hair))
    page.select_option("select[name=source_character_id]", source_id)
    page.click("#hairstyle-form button[type=submit]")
    hairstyle_id = re.search(r"hairstyle ([0-9a-f]+):", page.wait_for_selector(
        "#message.info:has-text('hairstyle')").inner_text()).group(1)
    page.wait_for_selector(f"#hairstyles tr[data-id='{hairstyle_id}'] [data-state=ready]", timeout=JOB_SECONDS * 1000)
    return hairstyle_id


def click_hairline_points(page, base: str, job_id: str, count: int = 5) -> None:
    """Open the drawing page of a job and click ``count`` points on its head, 12 mm above the current hairline."""
    page.goto(f"{base}/ui/#/hairline/{job_id}")
    page.wait_for_selector("#hairline-viewer canvas")
    page.wait_for_timeout(500)
    for x, y in page.evaluate(f"() => window.hairportHairline.screenPoints({count}, 0.012)"):
        page.mouse.click(x, y)
    assert page.get_attribute("#hairline-state", "data-points") == str(count)


def submit_hairline(page, api: httpx.Client) -> dict:
    """Send the drawn hairline; the new job opens in the viewer: its record once drawn."""
    page.click("#submit-hairline")
    page.wait_for_url(re.compile(r".*#/view/[0-9a-f]+$"))
    drawn_job = page.url.rsplit("/", 1)[1]
    page.wait_for_selector("#viewer[data-loaded=true]", timeout=JOB_SECONDS * 1000)
    return api.get(f"/v1/jobs/{drawn_job}").json()


def set_checkbox(page, name: str, checked: bool) -> None:
    page.set_checked(f"input[name=show-{name}]", checked)


def test_dashboard_end_to_end(deployment, inputs):
    base, api = deployment["base"], deployment["api"]
    with chromium() as page:
        enter_key(page, base, KEY)
        page.wait_for_selector("#key-state:text('key accepted')")
        assert page.url.endswith("/ui/#/") or page.url.endswith("/ui/")
        shot(page, "01-key")

        # two characters through the upload form, each listed with a drawn thumbnail
        page.goto(f"{base}/ui/#/characters")
        character_ids = {name: upload_character(page, inputs / f"{name}.obj", inputs / f"{name}.json")
                         for name in (SOURCE, HEAVY)}
        rows = page.locator("#characters tbody tr")
        assert rows.count() == 2
        page.wait_for_selector("#characters img[src^='data:image/png']")
        page.wait_for_timeout(500)
        assert page.locator("#characters img[src^='data:image/png']").count() == 2
        thumbnail = pixels(shot(page, "02-characters", f"#characters tr[data-id='{character_ids[HEAVY]}'] img"))
        assert count_drawn(thumbnail, background=(242, 244, 247)) > 0.05 * thumbnail.shape[0] * thumbnail.shape[1]

        # the groom, preprocessed
        hairstyle_id = upload_hairstyle(page, base, inputs / "groom.npz", character_ids[SOURCE])
        shot(page, "03-hairstyles")

        # a 1 x 2 batch with a hairline preset, watched to 100 %
        page.goto(f"{base}/ui/#/new")
        page.wait_for_selector("#retarget-form")
        page.check(f"input[name=hairstyle][value='{hairstyle_id}']")
        for character_id in character_ids.values():
            page.check(f"input[name=target][value='{character_id}']")
        page.select_option("select[name=hairline_preset]", "widows-peak")
        page.fill("input[name=hairline_amount]", "0.5")
        shot(page, "04-new-batch")
        page.click("#retarget-form button[type=submit]")
        page.wait_for_url(re.compile(r".*#/batches/[0-9a-f]+$"))
        batch_id = page.url.rsplit("/", 1)[1]
        page.wait_for_selector("#batch-percent:text('100 %')", timeout=JOB_SECONDS * 1000)
        shot(page, "05-batch-done")
        batch = api.get(f"/v1/batches/{batch_id}").json()
        assert batch["state"] == "done" and batch["counts"]["succeeded"] == 2, batch
        heavy_job = next(job["id"] for job in batch["jobs"] if job["target_character_id"] == character_ids[HEAVY])
        heavy = api.get(f"/v1/jobs/{heavy_job}").json()
        assert (heavy["hairline"]["preset"], heavy["hairline"]["amount"]) == ("widows-peak", 0.5)
        assert heavy["metrics"]["hairline"]["roots_moved"] > 0
        assert heavy["metrics"]["penetrating_particles"] == 0

        # the result in the viewer: body and strands drawn, red only for segments through the body (0 particles inside)
        page.goto(f"{base}/ui/#/view/{heavy_job}")
        page.wait_for_selector("#viewer[data-loaded=true]", timeout=60_000)
        stats = page.inner_text("#viewer-stats")
        assert f"{GROOM_STRANDS} of {GROOM_STRANDS} strands" in stats and "0 drawn inside" in stats
        # segments through the body between two particles outside: as many drawn (stride 1) as the report counts
        crossing = heavy["metrics"]["crossing_segments"]["count"]
        assert f"{crossing:,} drawn segments through it" in stats, stats
        assert page.locator("input[name=show-wrapped]").count() == 0  # the same topology: nothing was wrapped
        both = viewer_pixels(page, "06-viewer")
        area = both.shape[0] * both.shape[1]
        set_checkbox(page, "result", False)
        body_only = viewer_pixels(page, "06-viewer-body")
        set_checkbox(page, "result", True)
        set_checkbox(page, "body", False)
        strands_only = viewer_pixels(page, "06-viewer-strands")
        assert count_drawn(body_only) > 0.03 * area
        assert count_near(strands_only, RESULT_RGB, 12) > 300
        assert count_drawn(strands_only) < count_drawn(both)
        assert (count_red(strands_only) > 0) == (crossing > 0)

        # the source groom beside the result, on its own body, then over the result
        set_checkbox(page, "body", True)
        set_checkbox(page, "source", True)
        page.wait_for_selector("#viewer-stats:has-text('source: 300 of 300 strands')")
        beside = viewer_pixels(page, "06-viewer-source-beside")
        assert count_near(beside, SOURCE_RGB, 12) > 300 and count_near(beside, RESULT_RGB, 12) > 300
        # the source stands on its own body to the left: its strands' mean x well left of the result's
        assert mean_column_near(beside, RESULT_RGB, 12) - mean_column_near(beside, SOURCE_RGB, 12) > 0.2
        page.set_checked("input[name=side-by-side]", False)
        page.wait_for_timeout(1500)
        over = viewer_pixels(page, "06-viewer-source-over")
        assert count_near(over, SOURCE_RGB, 12) > 300
        # over the result: both grooms about the same vertical line
        assert abs(mean_column_near(over, RESULT_RGB, 12) - mean_column_near(over, SOURCE_RGB, 12)) < 0.05
        set_checkbox(page, "source", False)

        # a deliberately penetrating baseline overlaid: its particles inside the heavy body are red
        page.select_option("select[name=baseline]", "root-translate")
        page.click("#run-baseline")
        page.wait_for_selector("#viewer-stats[data-inside]:not([data-inside=''])", state="attached",
                               timeout=JOB_SECONDS * 1000)
        inside = int(page.get_attribute("#viewer-stats", "data-inside"))
        crossing = int(page.get_attribute("#viewer-stats", "data-crossing"))
        set_checkbox(page, "result", False)
        baseline = viewer_pixels(page, "07-viewer-baseline")
        assert inside > 20
        assert count_red(baseline) > 50
        # its segments through the body between two particles outside are counted and drawn (stride 1: all)
        baseline_job = page.locator("select[name=compare]").input_value()
        counted = api.get(f"/v1/jobs/{baseline_job}").json()["metrics"]["crossing_segments"]
        assert crossing == counted["count"] > 0, (crossing, counted, page.inner_text("#viewer-stats"))

        # a hairline drawn by clicking five points on the head, sent, opened in the viewer
        click_hairline_points(page, base, heavy_job)
        # a point dragged 15 px up the head moves, and stays one of five
        before = page.evaluate("() => window.hairportHairline.controlScreenPoints()")
        x, y = sorted(before)[2]
        page.mouse.move(x, y)
        page.mouse.down()
        page.mouse.move(x, y - 8, steps=4)
        page.mouse.move(x, y - 15, steps=4)
        page.mouse.up()
        after = page.evaluate("() => window.hairportHairline.controlScreenPoints()")
        assert len(after) == 5 and page.get_attribute("#hairline-state", "data-points") == "5"
        moved = max(after, key=lambda point: abs(point[1] - y) if abs(point[0] - x) < 8 else -1)
        assert abs(moved[0] - x) < 8 and 10 < y - moved[1] < 20
        shot(page, "08-hairline-drawn")
        drawn = submit_hairline(page, api)
        drawn_job = drawn["id"]
        shot(page, "09-hairline-result")
        assert drawn["state"] == "succeeded"
        assert len(drawn["hairline"]["curve"]["points"]) == 64
        assert drawn["metrics"]["hairline"]["roots_moved"] > 0
        assert drawn["metrics"]["penetrating_particles"] == 0

        # a result downloaded from the job page, byte for byte the API's
        page.goto(f"{base}/ui/#/jobs/{drawn_job}")
        with page.expect_download() as download:
            page.click("#downloads button[data-format=obj]")
        path = SHOTS / f"{drawn_job}.obj"
        download.value.save_as(path)
        shot(page, "10-downloaded")
        assert download.value.suggested_filename == f"{drawn_job}.obj"
        assert path.read_bytes() == api.get(f"/v1/jobs/{drawn_job}/result", params={"format": "obj"}).content
        assert path.read_text().count("\nv ") >= GROOM_STRANDS * 2
        assert page.errors == []


def upload_source(api: httpx.Client, inputs) -> tuple[str, str]:
    """The source character (with its rig) and the groom on it, through the API: their ids."""
    with open(inputs / f"{SOURCE}.obj", "rb") as mesh, open(inputs / f"{SOURCE}.json", "rb") as skeleton:
        character = api.post("/v1/characters", files={"mesh": mesh, "skeleton": skeleton}).json()["id"]
    with open(inputs / "groom.npz", "rb") as hair:
        hairstyle = api.post("/v1/hairstyles", files={"hair": hair}, data={"source_character_id": character}).json()["id"]
    return character, hairstyle


def upload_heavy(api: httpx.Client, inputs) -> str:
    """The heavy male (with its rig), through the API: its id."""
    with open(inputs / f"{HEAVY}.obj", "rb") as mesh, open(inputs / f"{HEAVY}.json", "rb") as skeleton:
        return api.post("/v1/characters", files={"mesh": mesh, "skeleton": skeleton}).json()["id"]


def open_new_form(page, base: str) -> None:
    """The key entered, and the new-retarget form open."""
    enter_key(page, base, KEY)
    page.wait_for_selector("#key-state:text('key accepted')")
    page.goto(f"{base}/ui/#/new")
    page.wait_for_selector("#retarget-form")


def job_state(api: httpx.Client, job_id: str) -> str:
    return api.get(f"/v1/jobs/{job_id}").json()["state"]


#: a retarget that runs for tens of seconds here (every iteration of 1000, no early stop): long enough to cancel
LONG_OPTIONS = {"max_iterations": 1000, "energy_tolerance": 0.0, "step_tolerance": 0.0}


def test_a_running_job_is_cancelled_and_retried_from_its_page(deployment, inputs):
    base, api = deployment["base"], deployment["api"]
    _, hairstyle = upload_source(api, inputs)
    with open(inputs / f"{HEAVY}.obj", "rb") as mesh, open(inputs / f"{HEAVY}.json", "rb") as skeleton:
        target = api.post("/v1/characters", files={"mesh": mesh, "skeleton": skeleton}).json()["id"]
    created = api.post("/v1/retargets", json={"hairstyle_id": hairstyle, "target_character_ids": [target],
                                               "options": LONG_OPTIONS, "output_format": "ply"})
    assert created.status_code == 202, created.text
    running = created.json()["jobs"][0]["id"]
    with chromium() as page:
        enter_key(page, base, KEY)
        page.wait_for_selector("#key-state:text('key accepted')")
        page.goto(f"{base}/ui/#/jobs/{running}")
        page.wait_for_selector("#job [data-state=running]", timeout=JOB_SECONDS * 1000)
        shot(page, "14-running")
        page.click("#cancel")
        page.wait_for_selector("#job [data-state=cancelled]", timeout=60_000)
        assert job_state(api, running) == "cancelled"
        assert page.locator("#cancel").count() == 0 and page.locator("#downloads button").count() == 0
        stopped_at = api.get(f"/v1/jobs/{running}").json()["progress"]
        assert 0 < stopped_at < 1 and f"{math.floor(100 * stopped_at)} %" in page.inner_text("#job")
        shot(page, "15-cancelled")

        # retried: a new job of the same pair, options and format, which opens in the page
        page.click("#retry")
        page.wait_for_url(re.compile(r".*#/jobs/(?!" + running + r")[0-9a-f]+$"))
        again = page.url.rsplit("/", 1)[1]
        first, second = api.get(f"/v1/jobs/{running}").json(), api.get(f"/v1/jobs/{again}").json()
        for field in ("hairstyle_id", "target_character_id", "options", "hairline", "output_format"):
            assert second[field] == first[field], field
        assert second["state"] in ("queued", "running")
        page.click("#cancel")  # and the worker is free again for the other tests
        page.wait_for_selector("#job [data-state=cancelled]", timeout=60_000)
        assert job_state(api, again) == "cancelled"
        assert page.errors == []


#: what the viewer's scene holds under the name "wrapped" (window.hairportViewer, dashboard/src/scene.js Viewer):
#: [vertices, faces, wireframe, visible] of its mesh, or null
WRAPPED_MESH = """() => {
  const group = window.hairportViewer?.groups.get("wrapped");
  let found = null;
  group?.traverse((child) => {
    if (child.isMesh) found = [child.geometry.attributes.position.count, child.geometry.index.count / 3,
                               child.material.wireframe, group.visible];
  });
  return found;
}"""


def count_blue(image: np.ndarray) -> int:
    """Pixels where blue leads red and green clearly (the wrap's wireframe; skin, hair and white do not)."""
    red, green, blue = (image[..., channel].astype(np.int16) for channel in range(3))
    return int(((blue > red + 40) & (blue > green + 20)).sum())


def test_a_wrap_chosen_in_the_form_is_run_and_drawn_over_the_target(deployment, inputs):
    """The form's wrap selector sends its mode: ``always`` wraps the source body onto a target of its own
    topology too; the job page shows the wrap's residual and the viewer draws the wrapped mesh over the target."""
    base, api = deployment["base"], deployment["api"]
    source, hairstyle = upload_source(api, inputs)
    target = upload_heavy(api, inputs)
    with chromium() as page:
        open_new_form(page, base)
        assert page.input_value("select[name=wrap]") == "auto"
        assert page.inner_text("#wrap-hint") == "targets of another mesh topology are wrapped: auto"
        assert page.eval_on_selector_all("select[name=wrap] option", "options => options.map((o) => o.value)") == [
            "auto", "always", "off"]
        page.check(f"input[name=hairstyle][value='{hairstyle}']")
        page.check(f"input[name=target][value='{target}']")
        page.select_option("select[name=wrap]", "always")
        shot(page, "20-new-wrap-always")
        page.click("#retarget-form button[type=submit]")
        page.wait_for_url(re.compile(r".*#/jobs/[0-9a-f]+$"))
        job_id = page.url.rsplit("/", 1)[1]
        assert api.get(f"/v1/jobs/{job_id}").json()["options"]["wrap"] == "always"
        page.wait_for_selector("#job [data-state=succeeded]", timeout=JOB_SECONDS * 1000)
        job = api.get(f"/v1/jobs/{job_id}").json()
        residual = job["metrics"]["wrap"]["residual_m"]
        assert job["metrics"]["input"]["target"]["topology"] == "same" and 0 < residual["mean"] < 2e-3
        row = page.wait_for_selector("#wrap-residual").inner_text()
        assert f"mean {1000 * residual['mean']:.2f} mm" in row and f"p95 {1000 * residual['p95']:.2f} mm" in row
        shot(page, "21-job-wrap-residual")

        # the wrapped layer is the source's mesh: its vertex and face counts, in the target's shape
        header = decode(api.get(f"/v1/jobs/{job_id}/body", params={"layer": "wrapped"}).content)[0]
        record = api.get(f"/v1/characters/{source}").json()
        assert (header["layer"], header["vertices"], header["faces"]) == ("wrapped", record["vertices"],
                                                                         record["faces"])

        page.goto(f"{base}/ui/#/view/{job_id}")
        page.wait_for_selector("#viewer[data-loaded=true]", timeout=60_000)
        toggle = page.locator("input[name=show-wrapped]")
        assert toggle.count() == 1 and not toggle.is_checked()
        assert page.evaluate(WRAPPED_MESH) is None
        set_checkbox(page, "result", False)  # the body alone, then the wireframe over it
        plain = viewer_pixels(page, "22-viewer-target")
        set_checkbox(page, "wrapped", True)
        page.wait_for_selector("#viewer[data-wrapped=true]")
        assert page.evaluate(WRAPPED_MESH) == [header["vertices"], header["faces"], True, True]
        assert page.get_attribute("#viewer", "data-wrapped-vertices") == str(header["vertices"])
        overlaid = viewer_pixels(page, "23-viewer-wrapped-over-target")
        area = overlaid.shape[0] * overlaid.shape[1]
        assert count_blue(plain) < 0.001 * area < 0.01 * area < count_blue(overlaid)
        set_checkbox(page, "wrapped", False)
        page.wait_for_selector("#viewer[data-wrapped=false]")
        assert page.evaluate(WRAPPED_MESH)[3] is False
        assert count_blue(viewer_pixels(page, "24-viewer-wrapped-hidden")) < 0.001 * area
        assert page.errors == []


def test_heads_in_millimetres_z_up_without_a_rig_through_the_page(deployment, inputs):
    """Open heads and a groom as a DCC tool writes them: units and axes inferred on upload, the groom
    anchored by the surface, the result drawn upright with the hair on top of the head, a hairline
    drawn on it (the head's frame from the mesh) and retargeted."""
    base, api = deployment["base"], deployment["api"]
    with chromium() as page:
        enter_key(page, base, KEY)
        page.wait_for_selector("#key-state:text('key accepted')")
        page.goto(f"{base}/ui/#/characters")
        heads = {}
        # the two heads, the heavy one again in hairport's own frame (metres, Y up), and again in
        # millimetres Z up but declared Y up (a wrong declaration, drawn lying down)
        uploads = {SOURCE: (f"{SOURCE}-head-mm.obj", "auto"), HEAVY: (f"{HEAVY}-head-mm.obj", "auto"),
                   "reference": (f"{HEAVY}-head.obj", "auto"), "declared-y": (f"{HEAVY}-head-mm.obj", "+y")}
        for name, (file, up_axis) in uploads.items():
            heads[name] = upload_character(page, inputs / file, up_axis=up_axis)
        for name in (SOURCE, HEAVY):
            record = api.get(f"/v1/characters/{heads[name]}").json()
            assert (record["units"], record["up_axis"], record["has_skeleton"]) == ("auto", "auto", False), record

        def thumbnail(name: str) -> np.ndarray:
            selector = f"#characters tr[data-id='{heads[name]}'] img[src^='data:image/png']"
            page.wait_for_selector(selector)
            return pixels(shot(page, f"16-head-{name}", selector)).astype(np.int16)

        page.wait_for_timeout(500)
        reference = thumbnail("reference")
        # the millimetre Z-up head is drawn as the same head in metres Y up; declared Y up, it is not
        upright = np.abs(thumbnail(HEAVY) - reference).mean()
        lying = np.abs(thumbnail("declared-y") - reference).mean()
        assert upright < 0.3 * lying, (upright, lying)

        hairstyle = upload_hairstyle(page, base, inputs / "fringe-mm.data", heads[SOURCE])

        page.goto(f"{base}/ui/#/new")
        page.wait_for_selector("#retarget-form")
        page.check(f"input[name=hairstyle][value='{hairstyle}']")
        page.check(f"input[name=target][value='{heads[HEAVY]}']")
        page.click("#retarget-form button[type=submit]")
        page.wait_for_url(re.compile(r".*#/jobs/[0-9a-f]+$"))
        job_id = page.url.rsplit("/", 1)[1]
        page.wait_for_selector("#job [data-state=succeeded]", timeout=JOB_SECONDS * 1000)
        metrics = api.get(f"/v1/jobs/{job_id}").json()["metrics"]
        assert metrics["anchoring"] == "surface" and metrics["penetrating_particles"] == 0
        assert (metrics["input"]["units"]["hair"], metrics["input"]["axes"]["up"]) == ("mm", "+z")

        page.goto(f"{base}/ui/#/view/{job_id}")
        page.wait_for_selector("#viewer[data-loaded=true]", timeout=60_000)
        assert f"{GROOM_STRANDS} of {GROOM_STRANDS} strands" in page.inner_text("#viewer-stats")
        view = viewer_pixels(page, "17-viewer-head-mm")
        hair_rows = rows_near(view, RESULT_RGB, 12)
        skin_rows = rows_near(view, (217, 199, 184), 40)
        assert len(hair_rows) > 20 and len(skin_rows) > 20
        # upright: the fringe covers the top of the head, above the middle of the face
        assert hair_rows.min() < skin_rows.min() + 0.1 * np.ptp(skin_rows)
        assert np.median(hair_rows) < np.median(skin_rows)

        # no rig: the head's frame comes from the mesh; five points clicked on the head
        click_hairline_points(page, base, job_id)
        shot(page, "18-hairline-head-mm")
        drawn = submit_hairline(page, api)
        assert drawn["state"] == "succeeded", drawn.get("error")
        assert drawn["metrics"]["hairline"]["head_frame"] == "mesh"
        assert drawn["metrics"]["hairline"]["roots_moved"] > 0 and drawn["metrics"]["penetrating_particles"] == 0
        shot(page, "19-hairline-head-mm-result")
        assert page.errors == []


def test_bad_input_through_the_page_shows_the_api_message(deployment, inputs):
    base = deployment["base"]
    with chromium() as page:
        enter_key(page, base, "expired-key")
        page.wait_for_selector("#key-state:text('key refused')")
        assert "unknown API key" in page.inner_text("#message")
        assert "unauthorized" in page.inner_text("#message")
        shot(page, "11-key-refused")

        enter_key(page, base, KEY)
        page.wait_for_selector("#key-state:text('key accepted')")
        page.goto(f"{base}/ui/#/characters")
        page.wait_for_selector("#characters table", state="attached")
        before = page.locator("#characters tbody tr").count()
        page.set_input_files("input[name=mesh]", str(inputs / "notes.txt"))
        page.click("#character-form button[type=submit]")
        message = page.wait_for_selector("#message:not(.info)").inner_text()
        assert "HTTP 415" in message and ".txt" in message
        shot(page, "12-wrong-file")
        page.reload()
        page.wait_for_selector("#characters table", state="attached")
        assert page.locator("#characters tbody tr").count() == before

        api = deployment["api"]
        character, hairstyle = upload_source(api, inputs)
        jobs_before = api.get("/v1/jobs").json()["total"]
        page.goto(f"{base}/ui/#/new")
        page.wait_for_selector("#retarget-form")
        page.check(f"input[name=hairstyle][value='{hairstyle}']")
        page.check(f"input[name=target][value='{character}']")
        page.fill("input[name=alpha]", "-5")
        page.click("#retarget-form button[type=submit]")
        message = page.wait_for_selector("#message:not(.info)").inner_text()
        assert "options.alpha" in message and "greater than or equal to 0" in message and "HTTP 422" in message
        assert api.get("/v1/jobs").json()["total"] == jobs_before
        shot(page, "13-absurd-option")
        assert page.url.endswith("#/new")  # nothing was created: the page stays
        page.click("nav a[href='#/jobs']")
        page.wait_for_selector("#jobs table")
        assert page.errors == []


def test_a_sequence_job_is_played_and_scrubbed_in_the_viewer(deployment, inputs):
    """A sequence of two characters started from the form (the heavy male checked first, then the source: the frames
    follow the order checked): the viewer shows a frame slider and a play button; each frame draws its own body and
    hair, none of it inside the body."""
    base, api = deployment["base"], deployment["api"]
    source, hairstyle = upload_source(api, inputs)
    heavy = upload_heavy(api, inputs)
    with chromium() as page:
        open_new_form(page, base)
        page.check(f"input[name=hairstyle][value='{hairstyle}']")
        page.check(f"input[name=target][value='{heavy}']")
        page.check(f"input[name=target][value='{source}']")
        assert page.inner_text("#frame-order") == f"frames in the order checked: 0: {heavy[:8]}, 1: {source[:8]}"
        page.select_option("select[name=frames_from]", "characters")
        page.select_option("select[name=output_format]", "usda")
        shot(page, "40-new-sequence")
        page.click("#retarget-form button[type=submit]")
        page.wait_for_url(re.compile(r".*#/jobs/[0-9a-f]+$"))
        job = wait_job(api, page.url.rsplit("/", 1)[1])
        assert job["state"] == "succeeded" and job["frames"] == 2 and job["output_format"] == "usda", job
        assert job["sequence"]["character_ids"] == [heavy, source] and job["sequence"]["temporal"] == 0
        assert job["metrics"]["penetrating_particles_max"] == 0
        page.goto(f"{base}/ui/#/view/{job['id']}")
        page.wait_for_selector("#viewer[data-loaded=true]", timeout=60_000)
        assert page.get_attribute("#viewer", "data-frame") == "0"
        assert page.get_attribute("#frame", "max") == "1"
        assert page.inner_text("#frame-label") == "frame 1 of 2 (time 0)"
        first = viewer_pixels(page, "41-viewer-sequence-frame-0")
        page.fill("#frame", "1")  # a range input takes fill(): the input event the slider listens to
        page.wait_for_selector("#viewer[data-frame='1']")
        assert page.inner_text("#frame-label") == "frame 2 of 2 (time 1)"
        second = viewer_pixels(page, "42-viewer-sequence-frame-1")
        changed = np.any(first != second, axis=2).mean()
        assert changed > 0.01, changed  # the source's body and hair are drawn where the heavy male's were not
        assert count_red(first) == count_red(second) == 0
        assert page.get_attribute("#viewer", "data-inside") == "0"
        page.click("#play")
        page.wait_for_selector("#viewer[data-frame='0']")  # playing wraps around to the first frame
        page.click("#play")
        assert page.inner_text("#play") == "Play"
        assert page.errors == []
