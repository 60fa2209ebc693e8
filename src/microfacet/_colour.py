"""The luminance of linear RGB, shared by the modules that weigh colours (no imports but NumPy)."""
from __future__ import annotations

import numpy as np

__all__ = ["LUMINANCE"]

#: Relative luminance ``Y`` of linear RGB with the Rec. 709 (sRGB) primaries and D65 white
#: (ITU-R BT.709; Mitsuba's ``luminance``): ``Y = rgb @ LUMINANCE``. Read-only.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
LUMINANCE.flags.writeable = False
