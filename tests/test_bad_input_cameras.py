"""A session's ``cameras.json`` that cannot be read: the report says so once, names the file, leaves
the arms-in-frames measures out (each view's record says why) and reports everything else."""

from __future__ import annotations

from pathlib import Path

import pytest
from demo_copies import demo_copy

from inspector.report.build import build_report

pytestmark = pytest.mark.slow  # a report of a rollout with video


@pytest.mark.parametrize("content, what", [('{"schema": "inspector.cameras/1", "cameras": ', "invalid JSON"),
                                           ('{"schema": "something else", "cameras": {}}', "schema")])
def test_a_broken_cameras_file_is_a_warning_and_the_rest_is_reported(tmp_path: Path, content: str, what: str) -> None:
    session = demo_copy(tmp_path, ["single_f000"])
    (session / "cameras.json").write_text(content)
    report = build_report([str(session)], jobs=1, use_cache=False)
    warnings = [w for w in report.get("warnings", []) if "cameras.json" in w]
    assert len(warnings) == 1 and what in warnings[0] and str(session / "cameras.json") in warnings[0]
    row = report["rollouts"][0]
    assert row["rmse_deg"] is not None and row["video_psnr_db"]  # the rest is measured
    for view, masked in row["video_psnr_masked"].items():
        assert masked["arm"] is None and "cameras.json" in masked["note"], view
