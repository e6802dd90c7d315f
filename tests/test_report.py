"""Tests of fgslam.report: the figures exist and the HTML page is self-contained."""

from __future__ import annotations

import dataclasses
from datetime import datetime, timezone
from pathlib import Path

import base64
from html.parser import HTMLParser

import numpy as np
import pytest

from fgslam.compare import EstimatorRun, Reference, compute_metrics, table_rows
from fgslam.report import write_report

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class PageParser(HTMLParser):
    """Collects every tag with its attributes, and the text of table cells by row."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.rows: list[list[str]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def synthetic_runs(kind: str = "ground_truth", n: int = 120):
    """A circle driven by the robot; an EKF that drifts, a smoother that is close, a batch."""
    rng = np.random.default_rng(2024)
    angle = np.linspace(0.0, 2.0 * np.pi, n)
    truth = np.c_[3.0 * np.sin(angle), 3.0 - 3.0 * np.cos(angle), angle]
    truth[:, 2] = (truth[:, 2] + np.pi) % (2 * np.pi) - np.pi
    landmarks = {i: (4.5 * np.cos(a), 3.0 + 4.5 * np.sin(a)) for i, a in enumerate(np.linspace(0, 6, 8))}
    drift = np.cumsum(rng.normal(0.0, 0.02, size=(n, 2)), axis=0)
    drift[0] = 0.0
    ekf = truth.copy()
    ekf[:, :2] += drift
    isam_final = truth.copy()
    isam_final[1:, :2] += rng.normal(0.0, 0.005, size=(n - 1, 2))
    isam_online = truth.copy()
    isam_online[:, :2] += 0.3 * drift

    def noisy(sigma):
        return {k: (x + rng.normal(0, sigma), y + rng.normal(0, sigma)) for k, (x, y) in landmarks.items()}

    runs = [
        EstimatorRun("ekf", ekf, ekf, noisy(0.1), np.full(n, 1e-3), 0.12),
        EstimatorRun("isam2", isam_online, isam_final, noisy(0.01), np.full(n, 5e-4), 0.06),
        EstimatorRun("batch", None, truth.copy(), dict(landmarks), None, 0.2),
    ]
    reference = Reference(kind, truth, landmarks)
    stamps_s = 100.0 + 0.5 * np.arange(n)
    return runs, reference, stamps_s, landmarks


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out_dir = tmp_path_factory.mktemp("report") / "nested" / "out"  # created by write_report
    runs, reference, stamps_s, _ = synthetic_runs()
    metrics = compute_metrics(runs, reference, log_path="data/circle.jsonl")
    html_path = write_report(out_dir, metrics, runs, reference, stamps_s, title="Circle run")
    parser = PageParser()
    parser.feed(html_path.read_text(encoding="utf-8"))
    return out_dir, html_path, metrics, parser


def test_returns_the_html_path(report):
    out_dir, html_path, _, _ = report
    assert html_path == out_dir / "report.html"
    assert html_path.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


def test_images_are_embedded_pngs(report):
    _, _, _, parser = report
    images = [attrs for tag, attrs in parser.tags if tag == "img"]
    # trajectories, position and heading error, time per step (no covariances: no NEES, no NIS)
    assert len(images) == 4
    prefix = "data:image/png;base64,"
    for attrs in images:
        src = attrs["src"]
        assert src.startswith(prefix)
        data = base64.b64decode(src[len(prefix):], validate=True)
        assert data.startswith(PNG_SIGNATURE)
        assert attrs.get("alt")


def test_page_is_valid_html5(report):
    """html5lib in strict mode raises on every parse error of the HTML5 spec (unclosed or
    misnested elements, bad attributes, stray text in tables, ...)."""
    import html5lib

    _, html_path, _, _ = report
    html5lib.HTMLParser(strict=True).parse(html_path.read_text(encoding="utf-8"))


def test_figure_table_lists_every_figure_and_links_inside_the_page(report):
    out_dir, _, _, parser = report
    ids = {attrs["id"] for _, attrs in parser.tags if "id" in attrs}
    links = [attrs["href"] for tag, attrs in parser.tags if tag == "a"]
    assert links and all(h.startswith("#") and h[1:] in ids for h in links)
    figure_rows = [r for r in parser.rows if len(r) == 3 and r[1].endswith(".png")]
    files = [r[1] for r in figure_rows]
    assert files == ["trajectories.png", "position_error.png", "heading_error.png", "nees.png", "nis.png",
                     "step_time.png"]
    for title, name, what in figure_rows:
        assert (out_dir / name).exists() or what.startswith("No ")


def test_page_has_no_external_links_or_scripts(report):
    _, html_path, _, parser = report
    for tag, attrs in parser.tags:
        for value in attrs.values():
            assert "http://" not in (value or "") and "https://" not in (value or "")
        assert not (tag == "script" and "src" in attrs)
        assert not (tag == "link" and "href" in attrs)
        assert tag not in ("script", "link", "iframe", "object", "embed")
    text = html_path.read_text(encoding="utf-8")
    assert "http://" not in text and "https://" not in text


def test_png_files_exist_and_are_reasonable(report):
    out_dir, _, _, _ = report
    assert not (out_dir / "nees.png").exists()
    assert not (out_dir / "nis.png").exists()
    for name in ("trajectories.png", "position_error.png", "heading_error.png", "step_time.png"):
        data = (out_dir / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE)
        assert 10_000 < len(data) < 400_000
        assert b"https://" not in data  # no matplotlib URL in the PNG metadata


def test_table_matches_the_terminal_table(report):
    _, html_path, metrics, parser = report
    headers, rows, _ = table_rows(metrics)
    assert parser.rows[0] == list(headers)
    assert parser.rows[1 : 1 + len(rows)] == [list(r) for r in rows]
    assert [row[0] for row in parser.rows[1 : 1 + len(rows)]] == ["ekf", "isam2", "batch"]
    text = html_path.read_text(encoding="utf-8")
    assert "data/circle.jsonl" in text
    assert "ground truth" in text


def test_smoothed_reference_aligned_run_and_truth_landmarks(tmp_path):
    runs, reference, stamps_s, landmarks = synthetic_runs("smoothed", n=60)
    # An estimate in another frame (rotated and shifted) must be aligned and still drawn.
    angle = 0.4
    c, s = np.cos(angle), np.sin(angle)
    other = runs[1].final.copy()
    other[:, :2] = other[:, :2] @ np.array([[c, -s], [s, c]]).T + (5.0, -2.0)
    other[:, 2] += angle
    runs.append(EstimatorRun("imported", None, other, {}, None, 0.0))
    metrics = compute_metrics(runs, reference, log_path="victoria.jsonl")
    assert metrics["imported"]["aligned"] is True
    truth = {k: (x + 0.05, y) for k, (x, y) in landmarks.items()}
    html_path = write_report(tmp_path, metrics, runs, reference, stamps_s, truth_landmarks=truth)
    text = html_path.read_text(encoding="utf-8")
    assert "smoothed solution" in text
    assert "imported" in text
    assert (tmp_path / "trajectories.png").stat().st_size > 10_000


def test_without_truth_the_error_columns_say_vs_reference(tmp_path):
    """A newcomer must not read distance to our own smoother as accuracy: without ground truth
    the error columns are named "vs ref" in the table, the HTML and its column glossary; with
    truth they keep their names."""
    runs, reference, stamps_s, _ = synthetic_runs("smoothed")
    metrics = compute_metrics(runs, reference, log_path="run.jsonl")
    headers, _, notes = table_rows(metrics)
    assert headers[1:4] == ("vs ref final m", "vs ref online m", "vs ref aligned m")
    assert not any(h.startswith("ATE") for h in headers)
    assert any("agreement with it, not accuracy" in n for n in notes)
    text = write_report(tmp_path, metrics, runs, reference, stamps_s).read_text(encoding="utf-8")
    assert "<dt>vs ref final m</dt>" in text and "not its accuracy" in text
    assert "<dt>ATE final m</dt>" not in text
    assert "distance in metres to the smoothed reference (no ground truth: agreement, not accuracy)" in text
    truth_runs, truth_reference, _, _ = synthetic_runs()
    assert table_rows(compute_metrics(truth_runs, truth_reference, log_path="run.jsonl"))[0][1] == "ATE final m"


def test_nees_figure_with_covariances_and_ground_truth(tmp_path):
    runs, reference, stamps_s, _ = synthetic_runs()
    n = len(stamps_s)
    covariance = np.broadcast_to(np.diag([0.01, 0.01, 0.001]), (n, 3, 3)).copy()
    runs = [dataclasses.replace(r, online_covariances=covariance) if r.online is not None else r for r in runs]
    metrics = compute_metrics(runs, reference, log_path="data/circle.jsonl")
    html_path = write_report(tmp_path, metrics, runs, reference, stamps_s)
    parser = PageParser()
    parser.feed(html_path.read_text(encoding="utf-8"))
    images = [attrs for tag, attrs in parser.tags if tag == "img"]
    assert len(images) == 5 and any("NEES" in a["alt"] for a in images)
    assert (tmp_path / "nees.png").read_bytes().startswith(PNG_SIGNATURE)
    assert metrics["ekf"]["nees_mean"] is not None


def test_nis_figure_and_ellipses(tmp_path):
    runs, reference, stamps_s, landmarks = synthetic_runs("smoothed")
    n = len(stamps_s)
    rng = np.random.default_rng(5)
    covariance = np.broadcast_to(np.diag([0.04, 0.02, 0.001]), (n, 3, 3)).copy()
    nis = rng.chisquare(2, size=300)
    runs[0] = dataclasses.replace(
        runs[0], online_covariances=covariance, nis=nis, nis_steps=np.sort(rng.integers(0, n, size=300)),
        landmark_covariances={k: np.diag([0.01, 0.02]) for k in runs[0].landmarks},
    )
    metrics = compute_metrics(runs, reference, log_path="data/circle.jsonl")
    assert metrics["ekf"]["nis_count"] == 300
    assert metrics["ekf"]["nis_mean"] == pytest.approx(float(np.mean(nis)))
    assert metrics["ekf"]["nees_mean"] is None  # smoothed reference: no NEES
    html_path = write_report(tmp_path, metrics, runs, reference, stamps_s)
    parser = PageParser()
    parser.feed(html_path.read_text(encoding="utf-8"))
    alts = [attrs["alt"] for tag, attrs in parser.tags if tag == "img"]
    assert len(alts) == 5 and any("NIS" in a for a in alts)
    assert (tmp_path / "nis.png").read_bytes().startswith(PNG_SIGNATURE)


def test_ellipse_is_the_95_percent_contour():
    from scipy.stats import chi2

    from fgslam.report import ellipse_xy

    cov = np.array([[0.09, 0.03], [0.03, 0.04]])
    centre = np.array([1.0, -2.0])
    outline = ellipse_xy(centre, cov, points=50)
    d = outline - centre
    mahalanobis_sq = np.einsum("ij,jk,ik->i", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis_sq, chi2.ppf(0.95, 2), rtol=1e-12)
    # and it goes all the way round
    angles = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    assert abs(angles[-1] - angles[0]) == pytest.approx(2 * np.pi, rel=1e-9)


def _screenshot_module():
    from scripts import report_screenshot

    return report_screenshot


def test_screenshot_crop_keeps_the_page_and_drops_the_empty_window():
    from PIL import Image

    shot = _screenshot_module()
    pixels = np.full((1000, 50, 3), 255, dtype=np.uint8)
    pixels[100:400, 10:40] = (30, 60, 90)  # the page's last content ends at row 399
    cropped = shot.crop_bottom_background(Image.fromarray(pixels), margin_px=10)
    assert cropped.size == (50, 410)


def test_screenshot_in_headless_chromium(report, tmp_path):
    """scripts/report_screenshot.py renders the page (Chromium is Debian's ``chromium``)."""
    from PIL import Image

    shot = _screenshot_module()
    if shot.find_browser() is None:
        pytest.skip("Chromium is not installed (apt-get install chromium)")
    _, html_path, _, _ = report
    out = tmp_path / "shot.png"
    assert shot.main([str(html_path), "--out", str(out)]) == 0
    with Image.open(out) as image:
        # every figure is about 600 px tall at this width: the page is rendered whole
        assert image.width == 1100 and image.height > 6 * 500
        assert len(np.unique(np.asarray(image.convert("L"))[::7, ::7])) > 20


# --------------------------------------------------------------------------- baselines and zoom


def runs_with_dead_reckoning(n: int = 120):
    """The synthetic runs (the EKF with pose covariances) plus a dead reckoning that drifts
    ~80 m away, with covariances and a map of its own far off: what must not take over the
    figures."""
    runs, reference, stamps_s, landmarks = synthetic_runs(n=n)
    truth = reference.trajectory
    drift = np.c_[np.linspace(0.0, 80.0, n), np.linspace(0.0, -35.0, n)]
    dr = truth.copy()
    dr[:, :2] += drift
    dr[:, 2] += np.linspace(0.0, 0.6, n)
    covariance = np.array([np.diag([0.01 + 0.5 * i, 0.01 + 0.5 * i, 0.001]) for i in range(n)])
    dr_landmarks = {k: (x + 60.0, y - 30.0) for k, (x, y) in landmarks.items()}
    runs[0] = dataclasses.replace(runs[0], online_covariances=np.broadcast_to(np.diag([0.01, 0.02, 0.001]), (n, 3, 3)))
    runs.append(EstimatorRun("dead_reckoning", dr, dr.copy(), dr_landmarks, np.full(n, 2e-5), 0.003,
                             online_covariances=covariance,
                             landmark_covariances={k: np.diag([4.0, 4.0]) for k in dr_landmarks}))
    return runs, reference, stamps_s, landmarks


def independent_view(runs, reference, margin=0.04, min_margin=0.3):
    """The overview's box computed here from the raw arrays (no alignment: every synthetic
    run starts at the reference's first pose)."""
    parts = [reference.trajectory[:, :2], np.array(list(reference.landmarks.values()))]
    for run in runs:
        if run.name == "dead_reckoning":
            continue
        parts.append(run.final[:, :2])
        if run.landmarks:
            parts.append(np.array(list(run.landmarks.values())))
    xy = np.vstack(parts)
    low, high = xy.min(axis=0), xy.max(axis=0)
    pad = max(margin * (high - low).max(), min_margin)
    return low[0] - pad, high[0] + pad, low[1] - pad, high[1] + pad


def lines_of_colour(ax, colour):
    from matplotlib.colors import same_color

    return [line for line in ax.get_lines() if same_color(line.get_color(), colour)]


DR_COLOUR = "#ff7f0e"  # dead reckoning is the 4th run: the 4th colour of the report's palette


def test_overview_is_zoomed_to_the_estimators_and_dead_reckoning_is_faint():
    from fgslam.report import trajectory_figure, trajectory_view

    runs, reference, _, _ = runs_with_dead_reckoning()
    expected = independent_view(runs, reference)
    assert trajectory_view(runs, reference) == pytest.approx(expected, abs=1e-12)
    fig = trajectory_figure(runs, reference)
    fig.canvas.draw()
    overview, detail = fig.axes
    assert overview.get_xlim() == pytest.approx(expected[:2], abs=1e-9)  # the box adapts, not the limits
    assert overview.get_ylim() == pytest.approx(expected[2:], abs=1e-9)
    assert runs[3].final[:, 0].max() > expected[1] + 50  # dead reckoning leaves the view: it is clipped
    dr_lines = lines_of_colour(overview, DR_COLOUR)
    assert len(dr_lines) == 1  # its trajectory only: no end marker, no pose ellipses
    assert dr_lines[0].get_alpha() < 0.5 and dr_lines[0].get_linewidth() < 1.0
    assert "baseline" in dr_lines[0].get_label()
    assert not [c for c in overview.collections if "dead_reckoning" in str(c.get_label())]  # no landmarks
    # the EKF keeps its full strength and its 12 ellipses
    ekf = lines_of_colour(overview, "#1f77b4")
    assert len(ekf) == 1 + 1 + 12 and min(line.get_alpha() or 1.0 for line in ekf) >= 0.8  # ellipses: 0.8


def test_show_and_drop_baseline():
    from fgslam.report import trajectory_figure, trajectory_view

    runs, reference, _, _ = runs_with_dead_reckoning()
    fig = trajectory_figure(runs, reference, baseline="show")
    fig.canvas.draw()
    overview = fig.axes[0]
    dr = runs[3]
    xmin, xmax = overview.get_xlim()
    ymin, ymax = overview.get_ylim()
    assert xmin <= dr.final[:, 0].min() and dr.final[:, 0].max() <= xmax
    assert ymin <= dr.final[:, 1].min() and dr.final[:, 1].max() <= ymax
    assert trajectory_view(runs, reference, baselines=()) == pytest.approx((xmin, xmax, ymin, ymax), abs=1e-9)
    assert len(lines_of_colour(overview, DR_COLOUR)) == 1 + 1 + 12 + 8  # line, end, pose and landmark ellipses
    fig = trajectory_figure(runs, reference, baseline="drop")
    assert not lines_of_colour(fig.axes[0], DR_COLOUR) and not lines_of_colour(fig.axes[1], DR_COLOUR)
    labels = fig.axes[-1].get_legend().get_texts()
    assert not [t for t in labels if "dead_reckoning" in t.get_text()]
    with pytest.raises(ValueError, match="baseline"):
        trajectory_figure(runs, reference, baseline="hide")


def test_detail_is_where_the_estimators_error_is_largest():
    from fgslam.report import detail_pose, trajectory_figure

    runs, reference, _, _ = runs_with_dead_reckoning()
    truth = reference.trajectory
    errors = {r.name: np.linalg.norm(r.final[:, :2] - truth[:, :2], axis=1) for r in runs}
    worst = np.maximum.reduce([errors["ekf"], errors["isam2"], errors["batch"]])
    k = int(np.argmax(worst))
    assert k > 0 and detail_pose(runs, reference) == k  # dead reckoning's far larger error is no candidate
    fig = trajectory_figure(runs, reference)
    fig.canvas.draw()
    detail = fig.axes[1]
    span = max(independent_view(runs, reference)[1] - independent_view(runs, reference)[0],
               independent_view(runs, reference)[3] - independent_view(runs, reference)[2])
    half = max(2.0 * worst[k], 0.02 * span, 0.02)
    assert detail.get_xlim() == pytest.approx((truth[k, 0] - half, truth[k, 0] + half), abs=1e-9)
    assert detail.get_ylim() == pytest.approx((truth[k, 1] - half, truth[k, 1] + half), abs=1e-9)
    text = "\n".join(t.get_text() for t in detail.texts)
    for name in ("ekf", "isam2", "batch"):
        assert f"{name}: {errors[name][k]:.3f} m" in text
    assert "dead_reckoning" not in text


def test_error_axes_follow_the_estimators_not_the_baseline(tmp_path):
    """Position and heading error: the y axis is scaled to the estimators, dead reckoning is
    drawn faint and runs off it."""

    from fgslam.report import plot_heading_errors, plot_position_errors

    runs, reference, stamps_s, _ = runs_with_dead_reckoning()
    truth = reference.trajectory
    figures = {}

    def capture(fig, ax, path, with_legend=True, **legend):
        figures[Path(path).name] = (fig, ax)
        return Path(path)

    import fgslam.report.time_plots as report

    original = report._legend_and_save
    report._legend_and_save = capture
    try:
        plot_position_errors(tmp_path / "p.png", runs, reference, stamps_s)
        plot_heading_errors(tmp_path / "h.png", runs, reference, stamps_s)
    finally:
        report._legend_and_save = original
    _, ax = figures["p.png"]
    others = [np.linalg.norm(r.final[:, :2] - truth[:, :2], axis=1) for r in runs[:3]]
    others.append(np.linalg.norm(runs[1].online[:, :2] - truth[:, :2], axis=1))
    top = max(float(e.max()) for e in others)
    assert ax.get_yscale() == "linear"
    assert ax.get_ylim() == pytest.approx((0.0, 1.08 * top), rel=1e-9)
    dr_error = np.linalg.norm(runs[3].final[:, :2] - truth[:, :2], axis=1)
    assert dr_error.max() > 10 * top
    faint = lines_of_colour(ax, DR_COLOUR)
    assert len(faint) == 1 and faint[0].get_alpha() < 0.5
    _, ax = figures["h.png"]
    wrap = lambda a: (a + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    heading = np.concatenate([np.degrees(wrap(r.final[:, 2] - truth[:, 2])) for r in runs[:3]]
                             + [np.degrees(wrap(runs[1].online[:, 2] - truth[:, 2]))])
    low, high = min(heading.min(), 0.0), max(heading.max(), 0.0)
    pad = 0.08 * max(high - low, 1e-3)
    assert ax.get_ylim() == pytest.approx((low - pad, high + pad), abs=1e-9)
    assert np.degrees(0.6) > high + pad  # dead reckoning's 34° heading error is off the axis


# --------------------------------------------------------------------------- provenance


def test_provenance_names_version_command_date_and_the_logs_hash(tmp_path):
    import shlex
    import shutil
    import subprocess
    import sys
    from datetime import datetime, timezone
    from importlib.metadata import version

    from fgslam.report import provenance

    log = tmp_path / "my run.jsonl"
    log.write_bytes(b'{"type": "header"}\n' + bytes(range(256)) * 40)
    if shutil.which("sha256sum"):  # coreutils, the reference
        expected = subprocess.run(["sha256sum", str(log)], capture_output=True, text=True, check=True).stdout.split()[0]
    else:
        import hashlib

        expected = hashlib.sha256(log.read_bytes()).hexdigest()
    before = datetime.now(timezone.utc).replace(microsecond=0)
    prov = provenance(log, ["ekf", "isam2"], command=["fgslam", "run", str(log), "--out", "o"])
    after = datetime.now(timezone.utc)
    assert prov["log_sha256"] == expected and prov["log_bytes"] == log.stat().st_size == 19 + 256 * 40
    assert prov["fgslam_version"] == version("fgslam") and prov["gtsam_version"] == version("gtsam")
    assert prov["command"] == f"fgslam run '{log}' --out o"
    assert shlex.split(prov["command"])[2] == str(log)
    stamp = datetime.strptime(prov["date_utc"], "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=timezone.utc)
    assert before <= stamp <= after
    assert prov["estimators"] == ["ekf", "isam2"] and prov["log"] == str(log)
    assert provenance(log, [])["command"] == shlex.join(sys.argv)  # default: this process's command line
    assert provenance(tmp_path / "missing.jsonl", [])["log_sha256"] is None
    fixed = provenance(None, [], command="x", now=datetime(2024, 2, 29, 23, 59, 58, tzinfo=timezone.utc))
    assert fixed["date_utc"] == "2024-02-29T23:59:58Z" and fixed["log"] is None


def test_page_shows_the_provenance(tmp_path):
    import hashlib

    import html5lib

    runs, reference, stamps_s, _ = runs_with_dead_reckoning()
    log = tmp_path / "grid <200>.jsonl"
    log.write_text('{"type": "header"}\n')
    metrics = compute_metrics(runs, reference, log_path=str(log))
    html_path = write_report(tmp_path / "out", metrics, runs, reference, stamps_s,
                             command=["fgslam", "run", str(log), "--estimators", "ekf,isam2,dead_reckoning"])
    text = html_path.read_text(encoding="utf-8")
    html5lib.HTMLParser(strict=True).parse(text)
    parser = PageParser()
    parser.feed(text)
    ids = {attrs.get("id") for _, attrs in parser.tags}
    assert "provenance" in ids
    section = text[text.index('id="provenance"'): text.index("</dl>", text.index('id="provenance"'))]
    assert hashlib.sha256(log.read_bytes()).hexdigest() in section
    assert "fgslam run &#x27;" in section and "grid &lt;200&gt;.jsonl" in section  # quoted and escaped
    assert "ekf, isam2, batch, dead_reckoning" in section
    assert "Baseline drawn faint in the figures: dead_reckoning" in text
    # what the lead writes into metrics.json can be passed as it is, and is what the page shows
    from fgslam.report import provenance

    prov = provenance(str(log), ["ekf"], command="fgslam run x", now=None)
    prov["date_utc"] = "2000-01-01T00:00:00Z"
    text = write_report(tmp_path / "out2", metrics, runs, reference, stamps_s, provenance_info=prov,
                        baseline="drop").read_text(encoding="utf-8")
    assert "2000-01-01T00:00:00Z" in text and "fgslam run x" in text
    assert "Baseline left out of the figures: dead_reckoning" in text


def test_provenance_stored_in_the_metrics_is_the_one_shown(tmp_path, monkeypatch):
    """The contract with ``fgslam run``: it puts ``provenance(...)`` under ``metrics["provenance"]``
    (a top-level key, not an estimator) before writing metrics.json; the page shows that."""
    import fgslam.compare.metrics as compare
    from fgslam.report import provenance

    monkeypatch.setattr(compare, "TOP_LEVEL_KEYS", tuple(compare.TOP_LEVEL_KEYS) + ("provenance",))
    runs, reference, stamps_s, _ = synthetic_runs(n=40)
    metrics = compute_metrics(runs, reference, log_path="data/circle.jsonl")
    metrics["provenance"] = provenance("data/circle.jsonl", [r.name for r in runs], command="fgslam run c",
                                       now=datetime(2030, 1, 2, 3, 4, 5, tzinfo=timezone.utc))
    text = write_report(tmp_path, metrics, runs, reference, stamps_s, command="ignored").read_text(encoding="utf-8")
    parser = PageParser()
    parser.feed(text)
    assert [r[0] for r in parser.rows[1:4]] == ["ekf", "isam2", "batch"]  # no "provenance" row
    section = text[text.index('id="provenance"'):]
    assert "2030-01-02T03:04:05Z" in section and "fgslam run c" in section and "ignored" not in section
