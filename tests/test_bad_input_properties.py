"""Property tests (hypothesis) of the readers: the session reader and the DreamZero-SO101 importer
take anything and answer with a session (or a report row) or one ``InspectorError``, never a crash,
and leave nothing half-written. The hand-made malformed cases are in ``test_bad_input_malformed.py``.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from test_bad_input_malformed import DEEP_JSON, HUGE_INT_JSON, npy_bytes

from inspector.data.session import SCHEMA, open_session
from inspector.errors import InspectorError
from inspector.units import JOINT_NAMES

# ==============================================================================================
# Hypothesis: the session reader takes anything and answers with a session or an InspectorError

_SESSION = {"schema": SCHEMA, "name": "p", "robot": "so101", "units": {"arm": "degrees", "gripper": "0..100"},
            "joint_names": list(JOINT_NAMES), "gt_source": {}, "model": {}}
_ROLLOUT = {"kind": "autoregressive", "prompt": "", "episode_index": None, "start_frame": 0, "fps": 30.0,
            "horizon": 4, "executed_per_chunk": 2, "frames_per_chunk": 2, "views": [],
            "gt": {"views": [], "episode_length": None}}

_json_scalars = (st.none() | st.booleans() | st.integers() | st.integers(-(10 ** 400), 10 ** 400)
                 | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=8)
                 | st.sampled_from(["", ".", "/", "~", "~nosuchuser/x", "a\x00b", "degrees", "range100",
                                    "so101", "single_chunk", "autoregressive", "front", "../x", SCHEMA]))
_json_values = st.recursive(_json_scalars, lambda inner: st.lists(inner, max_size=3)
                            | st.dictionaries(st.text(max_size=6), inner, max_size=3), max_leaves=8)


def _json_file(base: dict[str, Any], special: dict[str, st.SearchStrategy]) -> st.SearchStrategy[bytes]:
    """Bytes of a JSON file, mostly near ``base`` so that the reader gets past its first checks:
    ``base`` itself, fields set to plausible (``special``) or arbitrary values or dropped, any JSON
    document, or any bytes."""
    keys = sorted(set(base) | set(special) | {"unknown"})
    dump = lambda fields, dropped: json.dumps({k: v for k, v in {**base, **fields}.items()
                                               if k not in dropped}).encode()
    plausible = st.lists(st.sampled_from(sorted(special)), max_size=3, unique=True).flatmap(
        lambda ks: st.fixed_dictionaries({k: special[k] for k in ks})).map(lambda f: dump(f, ()))
    arbitrary = st.tuples(
        st.lists(st.sampled_from(keys), min_size=1, max_size=3, unique=True).flatmap(
            lambda ks: st.fixed_dictionaries({k: _json_values for k in ks})),
        st.sets(st.sampled_from(sorted(base)), max_size=2),
    ).map(lambda ed: dump(*ed))
    garbage = st.one_of(
        _json_values.map(lambda v: json.dumps(v).encode()),
        st.binary(max_size=40),
        st.sampled_from([DEEP_JSON.encode(), HUGE_INT_JSON.encode(), b"", b"\xff\xfe", b"[]", b"null"]),
    )
    return st.one_of(st.just(dump({}, ())), plausible, plausible, plausible, arbitrary, garbage)


_ints = st.integers(0, 6) | st.sampled_from([10 ** 6, 10 ** 13, 2 ** 62])
_DESCRS = ["<f8", ">f8", "<f4", "<f2", "<i8", "|u1", "|b1", "<c16", "<U3", "|O", "<M8[s]", "|V8", "zz", "<f16"]


def _npy_file(shapes: list[tuple[int, ...]]) -> st.SearchStrategy[bytes]:
    """Bytes of a ``.npy``: real arrays of plausible shape and any dtype/values, or made-up headers."""
    import io

    def save(shape: tuple[int, ...], dtype: str, value: float, slope: float) -> bytes:
        with np.errstate(all="ignore"):  # NaN or 1e308 cast to int: whatever numpy makes of it
            ramp = np.arange(int(np.prod(shape))).reshape(shape) * 0.01 * slope
            arr = (np.full(shape, value) + ramp).astype(dtype)
        buf = io.BytesIO()
        np.save(buf, arr)
        return buf.getvalue()

    values = st.one_of(
        st.floats(-1e3, 1e3),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([0.0, 1e30, -1e99, 1e101, 1.7e308, 5e-324]),
    )
    real = st.tuples(st.sampled_from(shapes) | st.lists(st.integers(0, 5), max_size=4).map(tuple),
                     st.sampled_from(["<f8", ">f8", "<f4", "<f2", "<i4", "|u1", "|b1", "<c16"]),
                     values, st.floats(-200, 200)).map(lambda t: save(*t))
    made_up = st.builds(npy_bytes, st.sampled_from(_DESCRS), st.lists(_ints, max_size=4).map(tuple),
                        st.binary(max_size=300), st.booleans())
    plausible = st.tuples(st.sampled_from(shapes), st.just("<f8"), st.floats(-1e3, 1e3),
                          st.floats(-200, 200)).map(lambda t: save(*t))
    return st.one_of(plausible, plausible, plausible, real, real, made_up, st.binary(max_size=100))


def _write_session(root: Path, session_json: bytes, rollout_json: bytes, actions: bytes,
                   gt_actions: bytes | None = None, states: bytes | None = None, twin: bool = False) -> Path:
    """A session with rollout ``r`` made of the given bytes (and a valid rollout ``twin``)."""
    r = root / "rollouts" / "r"
    (r / "gt").mkdir(parents=True)
    (root / "session.json").write_bytes(session_json)
    (r / "rollout.json").write_bytes(rollout_json)
    (r / "actions.npy").write_bytes(actions)
    if gt_actions is not None:
        (r / "gt" / "actions.npy").write_bytes(gt_actions)
    if states is not None:
        (r / "states.npy").write_bytes(states)
    if twin:
        (root / "rollouts" / "twin").mkdir()
        (root / "rollouts" / "twin" / "rollout.json").write_text(json.dumps(_ROLLOUT))
        np.save(root / "rollouts" / "twin" / "actions.npy", np.zeros((2, 4, 6)))
    return r


def _report_row_or_clean_error(rollout: Any) -> None:
    """The rollout's timeline and report row build, or fail with a one-line InspectorError."""
    from inspector.analysis.timeline import build_timeline
    from inspector.rows.rollout import rollout_summary

    try:
        tl = build_timeline(rollout)
        row = rollout_summary(tl, tl.all_video_metrics())
    except InspectorError as exc:
        assert "\n" not in str(exc)
        event("timeline refused")
        return
    event("report row")
    assert row["tag"] == rollout.tag
    json.dumps(row)  # the report's JSON can always be written




@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(session_json=_json_file(_SESSION, {
    "schema": st.sampled_from([SCHEMA, "inspector.session/2"]),
    "units": st.fixed_dictionaries({"arm": st.sampled_from(["degrees", "range100", "rad"])}),
    "joint_names": st.permutations(list(JOINT_NAMES)),
    "gt_source": st.fixed_dictionaries({"dataset": _json_scalars})}))
@pytest.mark.slow
def test_session_json_property(session_json: bytes) -> None:
    """Any ``session.json``: the session opens (its valid rollout loads) or ``open_session`` raises
    an InspectorError naming session.json in one line; never another exception."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "s"
        _write_session(root, session_json, json.dumps({**_ROLLOUT, "episode_index": 0}).encode(),
                       npy_bytes("<f8", (2, 4, 6), bytes(2 * 4 * 6 * 8)))
        try:
            session = open_session(root)
        except InspectorError as exc:
            assert str(root / "session.json") in str(exc) and "\n" not in str(exc)
            event("session refused")
            return
        assert list(session.rollouts) == ["r"] and not session.errors
        _report_row_or_clean_error(session.rollouts["r"])


def _array_bytes(shape: tuple[int, ...], values: st.SearchStrategy[float]) -> st.SearchStrategy[bytes]:
    import io

    def save(arr: np.ndarray) -> bytes:
        buf = io.BytesIO()
        np.save(buf, arr)
        return buf.getvalue()

    # numpy's own strategy: a fill value with some elements drawn apart, not each of up to 240 drawn
    # one by one (what made this property test slow), from the same values
    return arrays(np.float64, shape, elements=values).map(save)


_V30 = Path(__file__).resolve().parent / "data" / "lerobot" / "so101_v30"  # written by LeRobot
_joint_values = st.floats(-300, 300) | st.sampled_from([0.0, 1e30, -1e99, 1e100])
# A valid rollout of 2 autoregressive chunks of horizon 4, in all the ways a valid one may vary.
_VALID_ROLLOUT = st.fixed_dictionaries({
    **{k: st.just(v) for k, v in _ROLLOUT.items()},
    "executed_per_chunk": st.integers(1, 4), "frames_per_chunk": st.integers(1, 3),
    "start_frame": st.integers(0, 200), "episode_index": st.none() | st.integers(0, 3),
    "fps": st.floats(0.5, 1000), "gt": st.fixed_dictionaries({"episode_length": st.none() | st.integers(1, 400)}),
}).map(lambda d: json.dumps(d).encode())
_VALID_NPY = {
    "actions": _array_bytes((2, 4, 6), _joint_values),
    "gt": st.integers(1, 40).flatmap(lambda t: _array_bytes((t, 6), _joint_values)),
    "states": _array_bytes((3, 6), _joint_values),
}
_FUZZ = {
    "rollout.json": _json_file(_ROLLOUT, {
        "kind": st.sampled_from(["single_chunk", "autoregressive", "multi"]),
        "horizon": st.integers(-1, 6), "executed_per_chunk": st.integers(-1, 6),
        "frames_per_chunk": st.integers(-1, 3), "start_frame": st.integers(-1, 200) | st.just(10 ** 30),
        "episode_index": st.integers(-2, 3), "views": st.lists(st.sampled_from(["front", "top", "a b"]), max_size=2),
        "fps": st.floats(allow_nan=True, allow_infinity=True) | st.integers(-1, 10 ** 400),
        "gt": st.fixed_dictionaries({"episode_length": st.none() | st.integers(-1, 400) | st.booleans()})}),
    "actions": _npy_file([(1, 4, 6), (3, 4, 6), (0, 4, 6), (2, 4, 5), (2, 3, 6)]),
    "gt": _npy_file([(8, 6), (1, 6), (0, 6), (8, 5), (8,)]),
    "states": _npy_file([(2, 6), (4, 6), (3, 5)]),
}


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(broken=st.sampled_from(["nothing", *_FUZZ]), data=st.data(), twin=st.booleans(), with_dataset=st.booleans())
@pytest.mark.slow
def test_rollout_property(broken: str, data: st.DataObject, twin: bool, with_dataset: bool) -> None:
    """A valid-but-varied rollout with one of its files (``rollout.json``, ``actions.npy``,
    ``gt/actions.npy``, ``states.npy``) replaced by arbitrary bytes, with or without a GT dataset:
    the rollout loads or is recorded as an InspectorError naming its file in one line (the other
    rollout still loads); a loaded rollout's timeline and report row build or fail with
    InspectorError; never another exception."""
    files = {"rollout.json": data.draw(_VALID_ROLLOUT, "rollout.json"), "actions": data.draw(_VALID_NPY["actions"], "actions"),
             "gt": data.draw(st.none() | _VALID_NPY["gt"], "gt"),
             "states": data.draw(st.none() | _VALID_NPY["states"], "states")}
    if broken != "nothing":
        files[broken] = data.draw(_FUZZ[broken], f"broken {broken}")
    gt_source = {"dataset": str(_V30)} if with_dataset else {}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "s"
        r = _write_session(root, json.dumps({**_SESSION, "gt_source": gt_source}).encode(), files["rollout.json"],
                           files["actions"], files["gt"], files["states"], twin)
        session = open_session(root)
        assert session.tags() == (["r", "twin"] if twin else ["r"])
        assert not (set(session.rollouts) & set(session.errors))
        assert not twin or "twin" in session.rollouts  # one bad rollout never takes the others down
        if "r" in session.errors:
            message = str(session.errors["r"])
            assert str(r) in message and "\n" not in message
            event(f"rollout refused ({broken})")
            return
        rollout = session.rollouts["r"]
        assert rollout.actions.dtype == np.float64 and np.isfinite(rollout.actions).all()
        _report_row_or_clean_error(rollout)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(meta=_json_file({"tag": "x", "episode": 0, "frame_in_ep": 3, "prompt": "p", "episode_length": 30,
                        "predicted_frames": 9, "actions_pred": [[1.0] * 6] * 24, "actions_gt": [[2.0] * 6] * 24},
                       {"actions_pred": st.lists(st.lists(st.floats(allow_nan=True) | st.integers(), min_size=5,
                                                          max_size=6), min_size=0, max_size=3),
                        "episode_length": st.none() | st.integers(-2, 40) | st.booleans(),
                        "frame_in_ep": st.integers(-1, 10 ** 20), "predicted_frames": st.integers(-1, 3)}))
@pytest.mark.slow
def test_importer_property_all_or_nothing(meta: bytes) -> None:
    """Any single-chunk ``meta.json``: the import succeeds, or fails with InspectorError and
    leaves nothing next to the destination."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "src" / "f003"
        src.mkdir(parents=True)
        (src / "meta.json").write_bytes(meta)
        out = Path(tmp) / "out"
        out.mkdir()
        try:
            dest = import_dreamzero(src, out / "s", log=lambda _: None)
        except InspectorError as exc:
            assert "\n" not in str(exc) and str(src) in str(exc)
            assert list(out.iterdir()) == []
            event("import refused")
            return
        event("imported")
        session = open_session(dest)
        assert list(session.rollouts) == ["f003"] and not session.errors
        assert sorted(p.name for p in out.iterdir()) == ["s"]


@pytest.mark.parametrize("value", [10 ** 400, [[10 ** 400] * 6] * 24])
@pytest.mark.parametrize("key", ["actions_pred", "actions_gt"])
@pytest.mark.slow
def test_importer_refuses_numbers_past_float64(tmp_path, key, value):
    """JSON integers have no limit; one past float64's range is a one-line error naming the field
    (found by the property test above: an OverflowError escaped)."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    meta = {"tag": "x", "episode": 0, "frame_in_ep": 3, "prompt": "p", "episode_length": 30,
            "predicted_frames": 9, "actions_pred": [[1.0] * 6] * 24, "actions_gt": [[2.0] * 6] * 24, key: value}
    src = tmp_path / "src" / "f003"
    src.mkdir(parents=True)
    (src / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(InspectorError) as caught:
        import_dreamzero(src, tmp_path / "out", log=lambda _: None)
    assert key in str(caught.value) and str(src) in str(caught.value) and "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()


def test_npy_header_whose_size_overflows_is_an_error_not_a_warning(tmp_path):
    """A header of shape (2**62, 2**62): the size overflows int64. The header check refuses it in
    one line; numpy alone would warn ("overflow encountered") and go on."""
    import warnings

    from inspector.data.session import NpyFile

    path = tmp_path / "actions.npy"
    path.write_bytes(npy_bytes("<f8", (2 ** 62, 2 ** 62), b"", False))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        with pytest.raises(InspectorError) as caught:
            NpyFile(path, ("n", "m"))
    assert str(path) in str(caught.value) and "too large" in str(caught.value) and "\n" not in str(caught.value)
    assert [str(w.message) for w in seen] == []
