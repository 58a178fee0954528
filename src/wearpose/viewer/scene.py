"""What every picture of wearpose shares: the colours of estimate and ground truth, and which
sensor sites a kit puts on the body.

Colours are sRGB ``(r, g, b)`` in 0..255. The ground truth is a neutral light grey and every
estimate a saturated colour, so the two can be told apart without reading a label (the offline
page and the viser viewers both draw with these, each with a legend).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    from wearpose.body import BodyModel

Colour = tuple[int, int, int]

#: The (first) estimate: blue.
ESTIMATE_COLOUR: Colour = (70, 150, 245)
#: A second estimate on the same page (e.g. MI-Poser without MIM): orange.
SECOND_ESTIMATE_COLOUR: Colour = (240, 150, 50)
#: The ground truth: light grey.
TRUTH_COLOUR: Colour = (200, 200, 200)
#: Colours given to tracks in order when a caller names none (estimate, second estimate, green, truth).
PALETTE: tuple[Colour, ...] = (ESTIMATE_COLOUR, SECOND_ESTIMATE_COLOUR, (90, 200, 120), TRUTH_COLOUR)


def kit_sites(kit: str, body: BodyModel, sensor_names: Sequence[str] | None = None) -> tuple[str, ...]:
    """Body sites where ``kit``'s sensors sit on ``body``, in kit order, each site once.

    Args:
        kit: a registered kit name (:func:`wearpose.sensors.get_kit`).
        body: the body whose site names the kit's sites are resolved against (documented
            fallbacks taken silently here: the simulator reports them where they matter).
        sensor_names: only these sensors of the kit (default: all of them).

    Raises:
        KitError: unknown kit, or a sensor name the kit does not have.
    """
    # start-up: wearpose.sensors adds ~90 ms to import wearpose.viewer
    from wearpose.sensors import get_kit, resolve_sites
    from wearpose.sensors.kits import KitError  # start-up: wearpose.sensors.kits adds ~90 ms to import wearpose.viewer

    k = get_kit(kit)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sites, _ = resolve_sites(k, body.site_names, body.asset_id)
    names = [s.name for s in k.sensors] if sensor_names is None else list(sensor_names)
    unknown = [n for n in names if n not in sites]
    if unknown:
        raise KitError(f"kit {k.name!r} has no sensor(s) {unknown}; its sensors: {[s.name for s in k.sensors]}")
    return tuple(dict.fromkeys(sites[n] for n in names))
