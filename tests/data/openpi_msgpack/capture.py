"""Capture the bytes openpi-client's own ``msgpack_numpy`` packer makes, for the wire-format tests.

openpi-client pins ``numpy<2``, so it runs in a throwaway environment, never the project's::

    python3 -m venv /tmp/openpi-env
    pip download openpi-client==0.1.2 --no-deps -d /tmp/openpi-wheel
    /tmp/openpi-env/bin/pip install "numpy<2" "msgpack>=1.0.5" /tmp/openpi-wheel/openpi_client-0.1.2-py3-none-any.whl --no-deps
    /tmp/openpi-env/bin/python tests/data/openpi_msgpack/capture.py

It writes ``<name>.msgpack`` beside itself, one per message of :func:`messages`, and
``versions.txt`` (openpi-client, numpy, msgpack). ``tests/test_eval_wire.py`` builds the same
messages with this module's :func:`messages` and checks that ``inspector.eval.wire`` packs them
to these very bytes and unpacks these bytes to equal values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def messages() -> dict[str, object]:
    """What a client and a server send each other, with every kind of value the format carries."""
    ramp = np.arange(24, dtype=np.float32)[:, None] * np.float32(0.5)
    return {
        # the handshake: a server's config (a tuple travels as a list)
        "config": {"image_resolution": (480, 640), "n_external_cameras": 2, "needs_wrist_camera": False,
                   "needs_stereo_camera": False, "needs_session_id": True, "action_space": "joint_position"},
        # a request: images, state, prompt, session id, endpoint
        "observation": {
            "observation/exterior_image_0_left": (np.arange(4 * 6 * 3) % 251).astype(np.uint8).reshape(4, 6, 3),
            "observation/wrist_image_left": np.full((2, 3, 3), 200, np.uint8),
            "observation/joint_position": np.array([1.5, -20.25, 30.0, 45.125, -90.0], np.float64),
            "observation/gripper_position": np.array([12.5], np.float64),
            "prompt": "Pick the red cube",
            "session_id": "0f8e2b7c-4f61-4c3a-9a65-2d1e5b2b9f10",
            "endpoint": "infer",
        },
        "reset": {"session_id": "0f8e2b7c-4f61-4c3a-9a65-2d1e5b2b9f10", "endpoint": "reset"},
        # the two reply forms
        "reply_array": np.concatenate([ramp + np.float32(j) for j in range(6)], axis=1),
        "reply_map": {"action.joint_position": np.tile(ramp, (1, 5)), "action.gripper_position": ramp + 1},
        # predicted frames beside the actions
        "reply_video": {"action": np.zeros((3, 6), np.float32),
                        "video": (np.arange(2 * 4 * 4 * 3) % 256).astype(np.uint8).reshape(2, 4, 4, 3)},
        # every other dtype and shape the format carries
        "dtypes": {"f2": np.linspace(-1, 1, 5).astype(np.float16), "i2": np.array([-3, 7], np.int16),
                   "u4": np.array([1, 2**31], np.uint32), "be_i4": np.array([1, -2], ">i4"),
                   "bool": np.array([True, False]), "empty": np.zeros((0, 6), np.float64),
                   "zero_d": np.array(3.25), "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3))},
        "scalars": {"f4": np.float32(1.5), "f8": np.float64(2.25), "i8": np.int64(-3), "u1": np.uint8(7),
                    "b": np.bool_(True), "plain": [1, 2.5, "x", None, True, b"raw"]},
    }


def main() -> None:
    from importlib import metadata

    import msgpack
    from openpi_client import msgpack_numpy

    packer = msgpack_numpy.Packer()  # what openpi-client's WebsocketClientPolicy and the servers use
    for name, message in messages().items():
        (HERE / f"{name}.msgpack").write_bytes(packer.pack(message))
    (HERE / "versions.txt").write_text(f"openpi-client {metadata.version('openpi-client')}\n"
                                       f"numpy {np.__version__}\nmsgpack {'.'.join(map(str, msgpack.version))}\n")


if __name__ == "__main__":
    main()
