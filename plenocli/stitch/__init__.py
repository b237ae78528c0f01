"""Extended-FOV stitching of 2 (side by side) or 4 (2 x 2) views into one panorama.

The package, one concern per module (read :mod:`~plenocli.stitch.panorama` first: it is the
method on one page):

- ``views``: the view stack, layouts, a known radial distortion, the high-passed texture;
- ``rig``: a prism rig's views resampled into one common undistorted frame
  (ray model: :mod:`plenocli.optics.prism`);
- ``ncc``: masked normalised cross-correlation search for the integer shift;
- ``translation``: the sub-pixel shift of a pair (NCC search, ECC, photometric polish);
- ``photometric``: direct photometric refinement of a homography or a shift;
- ``homography``: SIFT + RANSAC + photometric refinement;
- ``nodata``: NaN pixels, isolated ones estimated for the measurements, holes kept out;
- ``registration``: priors, pairwise estimates and their global solve;
- ``compose``: canvas, warping, exposure matching, trimming, blending;
- ``quality``: overlap correlation and the local shifts left after stitching;
- ``panorama``: :func:`stitch` and its :class:`StitchReport`.

Both models work on high-passed images, so slow vignetting and gain differences do not pull the
fit. Geometry convention: see :mod:`plenocli.stitch.views`. Views, a rig or a transform the
stitch cannot vouch for raise :class:`StitchError` (a ValueError) with a one-line message.
"""

from plenocli.model.rig import PrismRig, ViewOptics
from plenocli.stitch.errors import StitchError
from plenocli.stitch.homography import estimate_homography
from plenocli.stitch.ncc import masked_ncc_surface, masked_ncc_window, search_shift
from plenocli.stitch.panorama import StitchReport, stitch
from plenocli.stitch.photometric import refine_homography
from plenocli.stitch.rig import common_to_view, view_to_common
from plenocli.stitch.translation import estimate_translation
from plenocli.stitch.views import BLENDS, LAYOUTS, MODELS, VIEW_NAMES, as_view_stack, undistort

__all__ = ["BLENDS", "LAYOUTS", "MODELS", "VIEW_NAMES", "PrismRig", "StitchError", "StitchReport",
           "ViewOptics",
           "as_view_stack", "common_to_view", "estimate_homography", "estimate_translation",
           "masked_ncc_surface", "masked_ncc_window", "refine_homography", "search_shift",
           "stitch", "undistort", "view_to_common"]
