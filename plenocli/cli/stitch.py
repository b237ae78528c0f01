import click

from plenocli.cli import options


@click.command(short_help="Stitch 2 or 4 views into an extended-FOV panorama.")
@click.argument("inputs", nargs=-1, required=True, type=options.InputFile())
@options.output_opt
@click.option("--views", default=None,
              help="Views to stitch, by name or page number, comma separated (e.g. A,B).")
@click.option("--layout", type=click.Choice(["auto", "1x2", "2x1", "2x2"]), default="auto",
              show_default=True, help="Arrangement, views row-major (2x2: S00,S01,S10,S11).")
@click.option("--model", type=click.Choice(["translation", "homography"]),
              default="translation", show_default=True, help="Geometric model between views.")
@click.option("--distortion",
              type=options.FiniteFloat(min=-1, max=1, min_open=True), default=0.0,
              show_default=True,
              help="Known radial distortion K1 removed first (r_d = r_u (1 + K1 r_u^2), r in "
                   "half-diagonals).")
@click.option("--rig", type=options.InputFile(), default=None,
              help="Prism rig YAML (focal_mm, sensor_mm, prism_n, prism_apex_deg, views): cancel "
                   "the prisms' distortion and search near the predicted overlap "
                   "(configs/rigs/).")
@click.option("--overlap",
              type=options.FiniteFloat(min=0, max=1, min_open=True, max_open=True), default=None,
              help="Expected overlap, fraction of the view (e.g. 0.2); restricts the search.")
@click.option("--overlap-tolerance",
              type=options.FiniteFloat(min=0, max=1, min_open=True, max_open=True),
              default=0.1, show_default=True,
              help="Tolerance on --overlap (fraction of the view).")
@click.option("--transform-in", type=options.InputFile(), default=None,
              help="Reapply a transform saved with --transform-out instead of registering.")
@click.option("--transform-out", type=options.OutputFile(".json"), default=None,
              help="Save the transform (JSON) to reapply to later captures of the same rig.")
@click.option("--blend", type=click.Choice(["feather", "multiband"]), default="feather",
              show_default=True, help="Seam blending.")
@click.option("--report", type=options.OutputFile(".json"), default=None,
              help="Write a JSON report (model, parameters, overlap, inliers, residual px).")
@options.preview_opt
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
