"""Tests of fgslam.report: the figures exist and the HTML page is self-contained."""

from __future__ import annotations

import dataclasses

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
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "scripts" / "report_screenshot.py"
    spec = importlib.util.spec_from_file_location("report_screenshot", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
