"""The tiny test method of ``docs/contributing.md`` ("Adding a method"): one subpackage and
one declaration. The test suite registers it (``register_method(METHOD)`` in-process, a
``wearpose.methods`` entry point for a ``wearpose serve`` process) and runs it end to end
through the commands the real methods use: ``wearpose train tiny``, ``evaluate``,
``estimate`` and ``serve`` (``tests/estimators/test_tinymethod.py``).

It is a real, if small, estimator: six IMU orientations (kit ``imu6``) -> the 24 local joint
rotations by a two-layer perceptron per frame, trained on simulated IMUs of corpus clips.
"""

from wearpose.estimators.method import EstimatorEntry, MethodSpec, TrainOption, Training

_P = "tests.estimators.tinymethod"

METHOD = MethodSpec(
    name="tiny",
    summary="tiny test method: 6 IMU orientations -> local joint rotations, a per-frame perceptron",
    estimators=(EstimatorEntry("tiny", f"{_P}.estimator:TinyEstimator", protocol=f"{_P}.entry:protocol"),),
    config=f"{_P}.estimator:TinyConfig",
    presets=("tiny",),
    kits=("imu6",),
    training=Training(
        entry=f"{_P}.entry:train_from_options",
        doc="""Train the tiny test method on simulated IMUs of the corpus train split.

        Example: wearpose train tiny --limit 2 --epochs 1 --out runs/tiny
        """,
        done="done: best val MPJAE {best:.1f} deg; checkpoints in {out_dir}",
        options=(TrainOption("hidden", None, "Override the hidden width.", int, min=1),),
        defaults={"config": "tiny"},
        help={"config": "Preset: tiny (the only one).", "out": "Run directory (default runs/tiny)."},
    ),
)
