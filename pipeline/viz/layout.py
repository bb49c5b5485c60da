"""The Rerun viewer's layout of a recording: where the 3-D eye starts, the camera images,
the IEKF state plots and the step log."""

from __future__ import annotations

import numpy as np

#: How far the 3-D view's eye starts from the objects (m), its angle (rad) beside the
#: camera's line of sight (so the completed back shows), and how much lower than the camera
#: it looks (the ratio of its elevation's sine to the camera's).
EYE_DISTANCE_M = 0.4


EYE_TURN_RAD = 0.9


EYE_LOWER = 0.6


def plots_path(entity: str) -> str:
    return "plots" if entity == "world" else f"plots/{entity.removeprefix('world/')}"


def eye_position(target: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """Where the 3-D view's eye starts: :data:`EYE_DISTANCE_M` from ``target``, turned
    :data:`EYE_TURN_RAD` about +z from the direction ``toward`` (the camera), with the sine
    of its elevation scaled by :data:`EYE_LOWER`."""
    toward = np.asarray(toward, dtype=float) / np.linalg.norm(toward)
    azimuth = np.arctan2(toward[1], toward[0]) + EYE_TURN_RAD
    sin_elevation = EYE_LOWER * toward[2]
    cos_elevation = np.sqrt(1.0 - sin_elevation**2)
    direction = [cos_elevation * np.cos(azimuth), cos_elevation * np.sin(azimuth), sin_elevation]
    return np.asarray(target, dtype=float) + EYE_DISTANCE_M * np.array(direction)


def blueprint(runs, camera_position_m: np.ndarray | None, plots: list[str]):
    """The viewer layout: the 3-D scene (eye on the objects, from beside the camera at
    ``camera_position_m`` in R, when known), the camera images, the IEKF state per
    iteration (plane, bias, gates) and the step log."""
    import rerun.blueprint as rrb

    references = [files.reference for files, _ in runs if files.reference is not None]
    eye = None
    if references:
        target = np.vstack(references).mean(axis=0)
        if camera_position_m is not None:
            toward = np.asarray(camera_position_m, dtype=float) - target
        else:
            toward = np.array([-1.0, -1.0, 1.0])
        position = eye_position(target, toward)
        eye = rrb.EyeControls3D(position=position, look_target=target, eye_up=[0.0, 0.0, 1.0])

    def series(name: str, part: str):
        return rrb.TimeSeriesView(
            origin="/", contents=[f"+ /{root}/{part}/**" for root in plots], name=name
        )

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                origin="world",
                name="robot frame",
                contents=["+ /**", "- /world/camera/image/depth"],
                eye_controls=eye,
            ),
            rrb.Vertical(
                rrb.Tabs(
                    rrb.Spatial2DView(
                        origin="world/camera/image",
                        contents=["+ $origin/rgb"],
                        name="colour",
                    ),
                    rrb.Spatial2DView(
                        origin="world/camera/image",
                        contents=["+ $origin/depth"],
                        name="depth",
                    ),
                ),
                series("bias (deg, mm)", "bias"),
                series("plane (deg, mm)", "plane"),
                series("gates", "gates"),
                rrb.TextLogView(origin="log", name="steps"),
                row_shares=[2.2, 1.2, 1.2, 1.2, 1.6],
            ),
            column_shares=[2.4, 1],
        ),
        collapse_panels=True,
    )
