import click

from plenocli.cli import options
from plenocli.pipeline.schema import refocus as schema


@click.command(short_help="Refocus a focused-plenoptic capture (Lanczos splatting, Eq. 3).")
@options.declared(schema.PARAMS)
@options.stage_command
def refocus(**params):
    """Refocus FRAMES with a lens grid: (X, Y) = s (g ((x, y) - c_ij) + c_ij).

    Every sensor pixel is splatted with a Lanczos kernel at (X, Y) into a sum and a weight map;
    the result is sum / weight, NaN where too few samples landed. Bayer frames give R, G, B
    pages (each colour splatted on its own, no demosaicing). With several g values the output
    holds one page per g (names like G@g3.5) and the sharpness of each is logged and stored.

    \b
    Example:
      plenocli refocus frames.tif --grid grid.yaml --s 0.2 --g 4 --view left -o left.tif
      plenocli refocus frames.tif --grid grid.yaml --g 2:6:0.5 -o sweep.tif --preview best.png
    """
    from plenocli.pipeline.stages.refocus import run

    run(**params)
