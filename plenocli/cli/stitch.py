import click

from plenocli.cli import options
from plenocli.pipeline.schema import stitch as schema


@click.command(short_help="Stitch 2 or 4 views into an extended-FOV panorama.")
@options.declared(schema.PARAMS)
@options.stage_command
def stitch(**params):
    """Stitch the views in INPUTS (2 side by side or 4 in 2 x 2) into one panorama TIFF.

    Views come from one file (dual-pixel A and B, the four sub-apertures of sai) or several (the
    left and right refocused images). Pages VIEW.R, VIEW.G, VIEW.B are one colour view; a file
    of pages R, G, B is one view named after the file. Bayer views are demosaiced and stitched
    as full-resolution RGB (develop the panorama for its colour). Exposure is matched per
    channel from the overlaps; the panorama is NaN where no view has data (outside the views,
    or clipped in every view covering it).

    \b
    Example:
      plenocli stitch flat.tif --views A,B -o panorama.tif --report stitch.json \\
          --transform-out rig.json --preview panorama.png
      plenocli stitch left.tif right.tif -o panorama.tif
      plenocli stitch views.tif --layout 2x2 --rig configs/rigs/quadpixel_pyramid.yaml \\
          -o panorama.tif
    """
    from plenocli.pipeline.stages.stitch import run

    run(**params)
