"""PS initialisation from a parallel grasp: plane offset and bias from the contacts
(paper section 4.1; docs/method.md §5).

* The plane keeps the proposed orientation (PCA: it contains ``e_a`` and z) and is moved so
  that it passes through the centre between the jaws: the mean of the two pads' contact
  centroids projected on the plane normal.
* The bias translation is the motion of the visible (front) surface along the front pad's
  normal: the difference between where the front pad's taxels touched and where the plan
  predicted the pad would touch the cloud. Only the component along the pad normal is
  observable from a flat pad (the tangential offset between the touched patch and the
  predicted one is a sampling difference, not object motion), so by default that is all
  that is kept. The bias yaw starts at zero.
* The contacts were made after the object moved, while the plane lives in the camera
  view's frame (``f_mb = f_b o f_m``); so the measured jaw centre is moved back by the bias:
  ``m_r = n . (centre_between_jaws - b_T)``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from pipeline.types import Contacts

BiasMode = Literal["normal", "full", "none"]


def pad_centroids(contacts: Contacts) -> dict[str, np.ndarray]:
    """Mean position ``(3,)`` of the touching taxels of every pad in contact."""
    return {
        str(pad): contacts.positions[contacts.pads == pad].mean(axis=0)
        for pad in np.unique(contacts.pads)
    }


def jaw_centre_offset(normal: np.ndarray, contacts: Contacts) -> float | None:
    """``n . centre`` for the centre between the two pads with the most touching taxels,
    or None when fewer than two pads touch."""
    pads, counts = np.unique(contacts.pads, return_counts=True)
    if len(pads) < 2:
        return None
    two = pads[np.argsort(-counts, kind="stable")[:2]]
    centroids = pad_centroids(contacts)
    return float(np.mean([centroids[str(p)] @ normal for p in two]))


def front_pad(contacts: Contacts, predicted_contacts: np.ndarray) -> str:
    """The pad whose contact centroid is nearest the predicted contacts' centroid."""
    target = predicted_contacts.mean(axis=0)
    centroids = pad_centroids(contacts)
    return min(centroids, key=lambda pad: float(np.linalg.norm(centroids[pad] - target)))


def contact_bias(
    contacts: Contacts, predicted_contacts: np.ndarray, mode: BiasMode = "normal"
) -> np.ndarray:
    """Bias translation ``(3,)`` from the front pad's contacts vs. the predicted ones.

    Args:
        contacts: taxels in contact after the grasp.
        predicted_contacts: ``(K, 3)`` cloud points the front pad was expected to touch.
        mode: ``"normal"`` keeps the component along the front pad's mean normal,
            ``"full"`` the whole centroid difference, ``"none"`` returns zero.

    Returns:
        Zero when there are no contacts or predictions, or mode is ``"none"``.
    """
    if mode == "none" or len(contacts) == 0 or len(predicted_contacts) == 0:
        return np.zeros(3)
    pad = front_pad(contacts, predicted_contacts)
    on_pad = contacts.pads == pad
    difference = contacts.positions[on_pad].mean(axis=0) - predicted_contacts.mean(axis=0)
    if mode == "full":
        return difference
    normal = contacts.normals[on_pad].mean(axis=0)
    normal /= np.linalg.norm(normal)
    return (difference @ normal) * normal
