"""The stitch's refusal: views, a rig or a transform it cannot vouch for."""


class StitchError(ValueError):
    """Views that do not overlap or have no texture, an ambiguous match, a 2 x 2 that does not
    close, a rig or a saved transform that does not fit the views. The message is one line for
    the person who gave them: what is wrong and what to do; the stage shows it as it is."""
