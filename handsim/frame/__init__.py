"""The Frame: one rendered view with all its labels, shared by envs, datasets and metrics.

=======================  ==========================================================================
module                   holds
=======================  ==========================================================================
:mod:`.record`           :class:`.Frame`, :class:`.ObjectLabel`, :class:`.Contact`, occluder codes
:mod:`.renderer`         :class:`.FrameRenderer`: the rules its labels follow, their tolerances
:mod:`.silhouettes`      the object silhouettes behind ``visib_fract`` (rendered alone, reused)
=======================  ==========================================================================
"""

from handsim.frame.record import (
    OCCLUDER_NONE,
    OCCLUDER_SCENE,
    OCCLUDER_SELF,
    Contact,
    Frame,
    ObjectLabel,
)
from handsim.frame.renderer import (
    LOD_TOLERANCE_PX,
    SENSOR_AGREEMENT_M,
    SILHOUETTE_TOLERANCE_PX,
    SKIN_DETAIL_CHOICES,
    VISIBILITY_TOLERANCE_M,
    FrameRenderer,
)

__all__ = [
    "Frame",
    "ObjectLabel",
    "Contact",
    "FrameRenderer",
    "OCCLUDER_NONE",
    "OCCLUDER_SELF",
    "OCCLUDER_SCENE",
    "VISIBILITY_TOLERANCE_M",
    "SENSOR_AGREEMENT_M",
    "SILHOUETTE_TOLERANCE_PX",
    "SKIN_DETAIL_CHOICES",
    "LOD_TOLERANCE_PX",
]
