import click

from plenocli.cli import options
from plenocli.pipeline.schema import develop as schema


@click.command(short_help="Develop a colour view into a photograph (TIFF, JPEG, PNG).")
@options.declared(schema.PARAMS)
@options.stage_command
def develop(**params):
    """Demosaic one view of INPUT, white-balance it, apply the camera's colour matrix and write
    an output-referred image (.tif 16-bit, .jpg or .png 8-bit) with ICC profile and EXIF.

    \b
    Example:
      plenocli develop views.tif --view S -o S.jpg --preview S.png
      plenocli develop views.tif --view A --wb-from white.tif --space display-p3 -o A.tif
    """
    from plenocli.pipeline.stages.develop import run

    run(**params)
