"""The table of bad inputs to every command, and damaged TIFF headers."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from tests.bad_inputs.files import (
    assert_one_line,
    run_bad,
)

# (id, argv with {i} = inputs folder and {o} = output folder, exit code, words in the message);
# a value the option's own type refuses is a usage error (exit 2), like any bad flag
CASES = [
    # refocus: g, s and grids
    # depth: a g bound past the shift the grid can measure (pitch / 0.5 px) is refused; it
    # depends on the grid file, so it is an input error (audit 12 E5: it was exit 2)
    ("depth-g-past-measurable", ["depth", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                 "--g", "2:1e308", "-o", "{o}/d.tif"], 1,
     ("--g with", "grid.yaml", "1 < g <=")),
    ("depth-g-galilean-past-measurable", ["depth", "{i}/rt/frames.tif", "--grid",
                                          "{i}/rt/grid.yaml", "--g", "-1e6:-2", "-o",
                                          "{o}/d.tif"], 1, ("--g", "<= g < -1")),
    # audit 15 E2: Python's int()/float() read '4_0' as 40 and digits of any script as digits
    *[(f"number-word-{k}", [*argv, "-o", f"{{o}}/{out}"], 2, words) for k, (argv, out, words) in
      enumerate([(["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g", "4_0"],
                  "r.tif", ("'--g'",)),
                 (["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g",
                   "2:\u0665:1"], "r.tif", ("'--g'",)),
                 (["bias", "{i}/frames.tif", "--smooth", "1_0"], "b.tif", ("'--smooth'",)),
                 (["develop", "{i}/biased.tif", "--view", "S", "--exposure", "\u0663"], "d.jpg",
                  ("'--exposure'",)),
                 (["develop", "{i}/biased.tif", "--view", "S", "--wb", "1_0,1,1"], "d.jpg",
                  ("'--wb'",))])],
    ("refocus-g0", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g", "0",
                    "-o", "{o}/r.tif"], 2, ("non-zero",)),
    ("refocus-g-neg", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g=-1",
                       "-o", "{o}/r.tif"], 1, ("Keplerian", "--g 1")),
    ("refocus-g-list-neg", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                            "--g", "2,-3", "-o", "{o}/r.tif"], 2, ("one sign",)),
    ("refocus-g-sweep-huge", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "0:1e9:1", "-o", "{o}/r.tif"], 2, ("at most 1000",)),
    ("refocus-g-sweep-1001", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "1:1001:1", "-o", "{o}/r.tif"], 2, ("at most 1000",)),
    ("refocus-g-list-1001", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                             "--g", ",".join(["4"] * 1001), "-o", "{o}/r.tif"], 2, ("1000",)),
    ("refocus-g-nan-range", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                             "--g", "nan:5:1", "-o", "{o}/r.tif"], 2, ("--g",)),
    ("refocus-g-inf", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g",
                       "inf", "-o", "{o}/r.tif"], 2, ("g",)),
    ("refocus-s1000", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                       "1000", "-o", "{o}/r.tif"], 2, ("'--s'", "x<=1")),
    ("refocus-g-empty-item", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "1,,2", "-o", "{o}/r.tif"], 2, ("'--g'",)),
    ("refocus-s-tiny", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                        "1e-9", "-o", "{o}/r.tif"], 1, ("at least 4 pixels",)),
    ("refocus-g-huge", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g",
                        "1e9", "-o", "{o}/r.tif"], 1, ("g = 1e+09", "no valid pixel")),
    ("refocus-mask-covers-lens", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                  "--view", "left", "--mask-width", "1e9", "-o", "{o}/r.tif"],
     2, ("--mask-width", "0 <= m < ")),
    ("refocus-s-nan", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                       "nan", "-o", "{o}/r.tif"], 2, ("'--s'",)),
    *[(f"refocus-grid-{name}", ["refocus", "{i}/rt/frames.tif", "--grid",
                                f"{{i}}/grid_{name}.yaml", "-o", "{o}/r.tif"], 1, words)
      for name, words in [("angle_nan", ("angle_rad",)), ("offset_nan", ("offset_xy",)),
                          ("pitch_nan", ("pitch_px",)), ("pitch_inf", ("pitch_px",)),
                          ("pitch_tiny", ("pitch_px",)), ("rotation_inf", ("angle_rad",)),
                          ("shape_negative", ("image_shape",)), ("lenses_nan", ("centres",)),
                          ("far_away", ("offset_xy",)),
                          ("pitch_beyond_frame", ("micro-images across",)),
                          ("lens_twice", ("listed twice",))]],
    *[(f"refocus-xml-{name}", ["refocus", "{i}/rt/frames.tif", "--grid",
                               f"{{i}}/calib_{name}.xml", "-o", "{o}/r.tif"], 1, words)
      for name, words in [("basis_zero", ("lens_base",)), ("basis_parallel", ("parallel",)),
                          ("diameter_inf", ("diameter",)), ("offset_nan", ("offset",))]],
    ("refocus-grid-not-yaml", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/not_yaml.yaml",
                               "-o", "{o}/r.tif"], 1, ("YAML",)),
    ("refocus-grid-misses-frame", ["refocus", "{i}/nan.tif", "--grid", "{i}/rt/grid.yaml",
                                   "-o", "{o}/r.tif"], 1,
     ("calibrated on a 160 x 120 image", "is 64 x 64", "same camera and crop")),
    ("refocus-all-nan", ["refocus", "{i}/nan.tif", "--grid", "{i}/grid_noshape.yaml",
                         "-o", "{o}/r.tif"], 1, ("no valid pixel",)),
    # sai: whole micro-images, enough of them
    ("sai-n7-512", ["sai", "{i}/f512.tif", "-n", "7", "-o", "{o}/v.tif"], 1,
     ("not a whole number", "511 rows and 511 columns")),
    ("sai-n2-511x509", ["sai", "{i}/f511x509.tif", "-n", "2", "-o", "{o}/v.tif"], 1,
     ("not a whole number",)),
    ("sai-n2-3x3", ["sai", "{i}/f3.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("at least",)),
    ("sai-n-huge", ["sai", "{i}/f512.tif", "-n", "1000000", "-o", "{o}/v.tif"], 1,
     ("at least",)),
    ("sai-n0", ["sai", "{i}/f512.tif", "-n", "0", "-o", "{o}/v.tif"], 2, ("'-n'", "x>=1")),
    ("sai-all-nan", ["sai", "{i}/nan.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("no valid",)),
    # bias: guard, smooth, over-scan
    ("bias-guard-huge", ["bias", "{i}/frames.tif", "--guard", "99999", "-o", "{o}/b.tif"], 1,
     ("guard",)),
    ("bias-smooth-huge", ["bias", "{i}/frames.tif", "--smooth", "100000", "-o", "{o}/b.tif"],
     1, ("smooth",)),
    ("bias-overscan-top-missing", ["bias", "{i}/left_only.tif", "--overscan", "top", "-o",
                                   "{o}/b.tif"], 1, ("over-scan",)),
    ("bias-active-beyond", ["bias", "{i}/active_beyond.tif", "-o", "{o}/b.tif"], 1,
     ("active_area",)),
    ("bias-active-empty", ["bias", "{i}/active_empty.tif", "-o", "{o}/b.tif"], 1,
     ("active_area",)),
    ("bias-all-clipped", ["bias", "{o}/../clipped_frames.tif", "-o", "{o}/b.tif"], 1,
     ("no valid pixel",)),
    ("bias-crop-huge", ["bias", "{i}/frames.tif", "--crop", "99999x99999", "-o", "{o}/b.tif"],
     1, ("crop",)),
    ("bias-guard-negative", ["bias", "{i}/frames.tif", "--guard=-5", "-o", "{o}/b.tif"], 2,
     ("'--guard'", "x>=0")),
    # decode: levels and sample types
    ("decode-black-nan", ["decode", "{i}/f512.tif", "--black", "nan", "-o", "{o}/d.tif"], 2,
     ("black",)),
    ("decode-black-inf", ["decode", "{i}/f512.tif", "--black", "inf", "-o", "{o}/d.tif"], 2,
     ("black",)),
    ("decode-white-neg", ["decode", "{i}/zlib.tif", "--white=-5", "-o", "{o}/d.tif"], 2,
     ("white",)),
    ("decode-white-nan", ["decode", "{i}/zlib.tif", "--white", "nan", "-o", "{o}/d.tif"], 2,
     ("white",)),
    ("decode-black-above-white", ["decode", "{i}/zlib.tif", "--black", "900", "--white", "800",
                                  "-o", "{o}/d.tif"], 1, ("white level",)),
    ("decode-black-negative", ["decode", "{i}/zlib.tif", "--black=-3", "-o", "{o}/d.tif"], 2,
     ("black",)),
    # own-6 (round 10): a black level above every sample made a frame of less than no light
    ("decode-black-above-every-sample", ["decode", "{i}/zlib.tif", "--black", "65000", "-o",
                                         "{o}/d.tif"], 1,
     ("black level 65000 DN (--black) is above every sample", "the largest is")),
    # a level the samples cannot reach: refused here, not written for bias to call damaged
    ("decode-white-beyond-samples", ["decode", "{i}/zlib.tif", "--white", "1e308", "-o",
                                     "{o}/d.tif"], 1, ("(--white)", "uint16", "65535")),
    ("decode-white-70000", ["decode", "{i}/zlib.tif", "--white", "70000", "-o", "{o}/d.tif"], 1,
     ("(--white)", "65535")),
    ("decode-black-huge", ["decode", "{i}/zlib.tif", "--black", "1e308", "-o", "{o}/d.tif"], 1,
     ("black level 1e+308 (--black)",)),
    # a raw records its own levels and pattern: one value over them is not taken (audit 7 W7)
    *[(f"decode-raw-{name}", ["decode", "{i}/dp.dng", f"--{name}", value, "-o", "{o}/d.tif"],
       2, (f"--{name}", "records its own black and white levels and CFA pattern"))
      for name, value in (("black", "100"), ("white", "9000"), ("cfa", "BGGR"))],
    *[(f"decode-{kind}", ["decode", f"{{i}}/{kind}.tif", "-o", "{o}/d.tif"], 1, (words,))
      for kind, words in (("complex", "real"), ("bool", "1-bit"), ("int8", "real"))],
    ("decode-all-nan", ["decode", "{i}/nan_plain.tif", "-o", "{o}/d.tif"], 1, ("no valid",)),
    # audit 7 E2: a frame name that reads as another page (colour page S.R of a view S, a sweep
    # page, a page number) or twice is a usage error, before the raw is read
    ("decode-frame-colour-page", ["decode", "{i}/dp.dng", "--frames", "S.R,A", "-o",
                                  "{o}/d.tif"], 2, ("colour page R of a view S",)),
    ("decode-frame-sweep-page", ["decode", "{i}/dp.dng", "--frames", "S@g3,A", "-o",
                                 "{o}/d.tif"], 2, ("'@g'",)),
    # audit 8 E9: a newline in a name split every later one-line message naming the view
    ("decode-frame-control", ["decode", "{i}/dp.dng", "--frames", "S\nError: x,A", "-o",
                              "{o}/d.tif"], 2, ("control character",)),
    ("decode-frame-number", ["decode", "{i}/dp.dng", "--frames", "S,1", "-o", "{o}/d.tif"], 2,
     ("page number",)),
    ("decode-frame-twice", ["decode", "{i}/dp.dng", "--frames", "S,S", "-o", "{o}/d.tif"], 2,
     ("given twice",)),
    ("decode-truncated", ["decode", "{i}/truncated.tif", "-o", "{o}/d.tif"], 1,
     ("truncated",)),
    # audit 9 E6: a raw DNG was "a monochrome capture" and "a plain (not plenocli) TIFF" to
    # develop, and stitch, crosstalk, depth, sai, calibrate each said something else
    ("develop-raw", ["develop", "{i}/dp.dng", "-o", "{o}/x.jpg"], 1,
     ("is a raw capture (DNG)", "develop takes as input", "decode it first")),
    ("bias-raw", ["bias", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("flat-white-raw", ["flat", "{i}/biased.tif", "--white", "{i}/dp.dng", "-o", "{o}/x.tif"], 1,
     ("raw capture (DNG)", "flat takes as white")),
    ("stitch-raw", ["stitch", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("crosstalk-raw", ["crosstalk", "{i}/dp.dng", "-o", "{o}/x.json"], 1,
     ("raw capture (DNG)",)),
    ("depth-raw", ["depth", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    # audit 9 W9: past 12 px a half-pixel view's blur leaves side lobes matched at wrong
    # shifts with clear confidence (bands of 16-31 px read 7-15 px, signs flipped)
    ("depth-max-disparity-past-measured", ["depth", "{i}/biased.tif", "--max-disparity", "24",
                                           "-o", "{o}/x.tif"], 2, ("--max-disparity", "12")),
    ("simulate-disparity-past-measured", ["simulate", "dualpixel-depth", "-o", "{o}/s",
                                          "--param", "disparities=[-20,-2,-1,0,1,2,3,20]"], 2,
     ("disparities", "12")),
    ("sai-raw", ["sai", "{i}/dp.dng", "-n", "2", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("calibrate-raw", ["calibrate", "{i}/dp.dng", "-o", "{o}/g.yaml"], 1,
     ("raw capture (DNG)",)),
    # audit 9 E3: a view named twice in --views was exit 1, --frames S,S a usage error
    ("stitch-views-twice", ["stitch", "{i}/biased.tif", "--views", "A,A", "-o", "{o}/p.tif"], 2,
     ("'A' is named twice",)),
    # audit 12 E5: a rig on `bias --crop` views was refused saying to register without it,
    # and the registration said to give the rig; the rig describes the whole active area
    ("stitch-rig-on-cropped-views", ["stitch", "{i}/biased_crop.tif", "--views", "A,B", "--rig",
                                     "{i}/dualpixel_prism.yaml", "-o", "{o}/p.tif"], 1,
     ("bias --crop 24x32", "whole active area", "without --crop")),
    # audit 16 M2: a Bayer view negated, chosen by --views, was told to pass the rig (and with
    # it "no reliable overlap"): its demosaic had clipped it to 0, hiding the sign
    *[(f"stitch-bayer-view-negated{'-rig' * bool(rig)}",
       ["stitch", "{i}/biased_neg_b.tif", "--views", "A,B", *rig, "-o", "{o}/p.tif"], 1,
       ("view 1's levels are mostly below zero", "check how view 1 was made"))
      for rig in ([], ["--rig", "{i}/dualpixel_prism.yaml"])],
    ("decode-huge-header", ["decode", "{i}/huge.tif", "-o", "{o}/d.tif"], 1, ("200000",)),
    ("decode-empty-file", ["decode", "{i}/empty.tif", "-o", "{o}/d.tif"], 1,
     ("empty.tif", "not a raw capture")),
    *[(f"decode-{name}", ["decode", f"{{i}}/{name}", "-o", "{o}/d.tif"], 1, words)
      for name, words in [("trunc.png", ("unreadable",)), ("trunc.bmp", ("unreadable",)),
                          ("zlib_trunc.tif", ("truncated",)), ("inf.tif", ("infinite",)),
                          ("volume.tif", ("shape",)), ("garbage.tif", ("damaged",)),
                          ("huge.png", ("more than",))]],
    ("decode-frames-empty", ["decode", "{i}/dp.dng", "--frames=", "-o", "{o}/d.tif"], 2,
     ("'--frames'", "empty")),
    ("decode-frames-count", ["decode", "{i}/zlib.tif", "--frames", "S,A,B", "-o", "{o}/d.tif"],
     1, ("3 frame names",)),
    # own-5 (round 10): --frames A,S relabelled a DNG's S and A (bias then wrote the real S as
    # A, exit 0); a raw that names its frames takes no --frames, as it takes no --black
    ("decode-frames-of-a-raw", ["decode", "{i}/dp.dng", "--frames", "A,S", "-o", "{o}/d.tif"],
     2, ("--frames", "names its own frames (S,A)", "leave --frames out")),
    ("decode-calib-without-raytrix", ["decode", "{i}/dp.dng", "--calib", "{i}/rt/calib.xml",
                                      "-o", "{o}/d.tif"], 2, ("--calib goes with --camera "
                                                              "raytrix", "read as a DNG")),
    ("decode-raytrix-bad-calib", ["decode", "{i}/f512.tif", "--camera", "raytrix", "--calib",
                                  "{i}/calib_basis_zero.xml", "-o", "{o}/d.tif"], 1,
     ("lens_base",)),
    ("decode-cfa-bad", ["decode", "{i}/f512.tif", "--cfa", "RRGB", "-o", "{o}/d.tif"], 2,
     ("'--cfa'",)),
    # flat
    # (a white flat-fielded by itself only with --save-gain: one file given twice otherwise)
    ("flat-median-huge", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--median",
                          "100001", "-o", "{o}/f.tif", "--save-gain", "{o}/g.tif"], 1,
     ("median",)),
    ("flat-white-nan", ["flat", "{i}/nan.tif", "--white", "{i}/nan.tif", "-o", "{o}/f.tif",
                        "--save-gain", "{o}/g.tif"], 1, ("no valid pixel",)),
    ("flat-truncated-white", ["flat", "{i}/biased.tif", "--white", "{i}/truncated.tif", "-o",
                              "{o}/f.tif"], 1, ("truncated",)),
    ("flat-percentile-nan", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif",
                             "--reference", "percentile", "--percentile", "nan", "-o",
                             "{o}/f.tif"], 2, ("percentile",)),
    ("flat-floor-nan", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--floor", "nan",
                        "-o", "{o}/f.tif"], 2, ("floor",)),
    # a value the option's own rule refuses, or an option with no effect: usage errors naming it
    ("flat-median-even", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--median",
                          "10", "-o", "{o}/f.tif"], 2, ("'--median'", "10 is not odd")),
    # audit 8 W6: S = A + B named in --views beside A only passed (r = 68 %, exit 0)
    ("crosstalk-views-sum", ["crosstalk", "{i}/biased.tif", "--views", "A,S", "-o",
                             "{o}/c.json"], 1, ("S is the sum A + B",)),
    ("crosstalk-tile-odd", ["crosstalk", "{i}/biased.tif", "--tile", "3", "-o", "{o}/c.json"], 2,
     ("'--tile'", "3 is not even")),
    # audit 7 E17: one source of the gain is a usage error, as other option pairs are
    ("flat-white-and-gain", ["flat", "{i}/biased.tif", "--white", "{i}/biased_copy.tif", "--gain",
                             "{i}/biased.tif", "-o", "{o}/f.tif"], 2, ("exactly one of",)),
    ("flat-no-white-nor-gain", ["flat", "{i}/biased.tif", "-o", "{o}/f.tif"], 2,
     ("exactly one of",)),
    ("flat-gain-with-median", ["flat", "{i}/biased.tif", "--gain", "{i}/biased.tif", "--median",
                               "7", "-o", "{o}/f.tif"], 2, ("--median makes a gain",)),
    ("flat-gain-with-floor", ["flat", "{i}/biased.tif", "--gain", "{i}/biased.tif", "--floor",
                              "0.5", "-o", "{o}/f.tif"], 2, ("--floor makes a gain",)),
    ("flat-percentile-with-max", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif",
                                  "--percentile", "0", "-o", "{o}/f.tif"], 2,
     ("--percentile applies to --reference percentile",)),
    ("refocus-mask-width-full-view", ["refocus", "{i}/rt/frames.tif", "--grid",
                                      "{i}/rt/grid.yaml", "--mask-width", "5", "-o",
                                      "{o}/r.tif"], 2, ("--mask-width applies to half",)),
    ("flat-not-bias-corrected", ["flat", "{i}/frames.tif", "--white", "{i}/frames.tif", "-o",
                                 "{o}/f.tif", "--save-gain", "{o}/g.tif"], 1,
     ("run plenocli bias first",)),
    ("flat-white-not-bias-corrected", ["flat", "{i}/biased.tif", "--white", "{i}/frames.tif",
                                       "-o", "{o}/f.tif"], 1, ("run plenocli bias first",)),
    ("flat-gain-not-gain", ["flat", "{i}/biased.tif", "--gain", "{i}/biased_copy.tif", "-o",
                            "{o}/f.tif"], 1, ("`plenocli bias` output", "flat takes as gain")),
    # audit 13 E3: a photograph as --gain was "no CFA in its plenocli metadata ... use the output
    # of plenocli bias": it is named, as every other input names it
    *[(f"flat-gain-{name}", ["flat", "{i}/biased.tif", "--gain", f"{{i}}/{name}", "-o",
                             "{o}/f.tif"], 1, (what, "flat takes as gain the gain map"))
      for name, what in (("photo.tif", "`plenocli develop` photograph"),
                         ("photo.jpg", "`plenocli develop` photograph"),
                         ("linear.tif", "`plenocli develop --linear` output"))],
    ("flat-white-other-size", ["flat", "{i}/biased.tif", "--white", "{i}/f512.tif", "-o",
                               "{o}/f.tif"], 1, ("white image",)),
    # refocus and sai: other options
    *[(f"refocus-{opt}-{value}", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                  f"--{opt}", value, "-o", "{o}/r.tif"], 2, (f"'--{opt}'",))
      for opt, value in [("radius", "nan"), ("radius", "-1"), ("min-weight", "nan"),
                         ("mask-width", "inf"), ("mask-width", "-1")]],
    ("sai-grid-hex", ["sai", "{i}/rt/frames.tif", "-n", "2", "--grid", "{i}/rt/grid.yaml", "-o",
                      "{o}/v.tif"], 1, ("square",)),
    ("sai-of-views", ["sai", "{o}/../views.tif", "-o", "{o}/v.tif"], 1, ("`plenocli sai` output",)),
    ("sai-dualpixel-views", ["sai", "{i}/biased.tif", "-o", "{o}/v.tif"], 1, ("dual-pixel",)),
    ("sai-micro-image-mono", ["sai", "{i}/f512.tif", "--cfa-layout", "micro-image", "-o",
                              "{o}/v.tif"], 1, ("no CFA",)),
    ("sai-cfa-layout", ["sai", "{i}/f512.tif", "--cfa-layout", "diagonal", "-o", "{o}/v.tif"],
     2, ("cfa-layout",)),
    # metadata a stage reads, edited or damaged
    *[(f"bias-{name}", ["bias", f"{{i}}/{name}.tif", "-o", "{o}/b.tif"], 1, (word,))
      for name, word in [("meta_black", "black_level"), ("meta_black_short", "black_level"),
                         ("meta_white", "white_level"), ("meta_cfa", "cfa"),
                         ("meta_cfa_int", "cfa"), ("meta_masked", "masked area"),
                         ("meta_provenance", "provenance"), ("meta_views_twice", "twice"),
                         ("meta_black_negative", "black_level"), ("meta_future", "format 99"),
                         ("meta_not_json", "damaged")]],
    ("info-meta-not-json", ["info", "{i}/meta_not_json.tif"], 1, ("damaged",)),
    ("sai-meta-cfa", ["sai", "{i}/meta_cfa.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("cfa",)),
    *[(f"refocus-{name}", ["refocus", "{i}/rt/frames.tif", "--grid", f"{{i}}/{name}.yaml",
                           "-o", "{o}/r.tif"], 1, (word,))
      for name, word in [("grid_int", "lens grid"), ("grid_pitch_text", "abc"),
                         ("grid_offset_short", "offset_xy"), ("grid_lattice", "lattice"),
                         ("grid_origin_nan", "sensor_origin"),
                         ("grid_origin_negative", "sensor_origin"),
                         ("grid_lens_row_short", "lens grid"),
                         ("grid_shape_3d", "image_shape")]],
    ("sai-grid-pitch-below-n", ["sai", "{i}/rt/frames.tif", "--grid", "{i}/grid_square_tiny.yaml",
                                "-n", "3", "-o", "{o}/v.tif"], 1, ("sub-apertures",)),
    ("info-grid-origin-nan", ["info", "{i}/grid_origin_nan.yaml"], 1, ("sensor_origin",)),
    # crosstalk
    ("crosstalk-views-twice", ["crosstalk", "{i}/biased.tif", "--views", "B, B", "-o",
                               "{o}/c.json"], 2, ("'B' is named twice",)),  # audit 9 E3
    # audit 9 E12: one view named was "holds one view (A; pages R, G, B are its colours)"
    ("crosstalk-views-one", ["crosstalk", "{i}/biased.tif", "--views", "A", "-o", "{o}/c.json"],
     2, ("--views names one view (A): cross-talk compares two or more",)),
    ("crosstalk-views-twice-by-number", ["crosstalk", "{i}/biased.tif", "--views", "A,0", "-o",
                                         "{o}/c.json"], 1, ("twice",)),
    ("crosstalk-same-white-twice", ["crosstalk", "{i}/unmasked0.tif", "{i}/unmasked0.tif",
                                    "{i}/unmasked2.tif", "{i}/unmasked3.tif", "--intended",
                                    "S00,S01,S10,S11", "--mixing-out", "{o}/m.tif", "-o",
                                    "{o}/c.json"], 1, ("given twice",)),
    ("crosstalk-whites-not-masked", ["crosstalk", "{i}/unmasked0.tif", "{i}/unmasked1.tif",
                                     "{i}/unmasked2.tif", "{i}/unmasked3.tif", "--intended",
                                     "S00,S01,S10,S11", "--mixing-out", "{o}/m.tif", "-o",
                                     "{o}/c.json"], 1, ("not brighter",)),
    ("unmix-same-views-twice", ["unmix", "{i}/unmasked0.tif", "{i}/unmasked0.tif", "--mixing",
                                "{i}/unmasked1.tif", "-o", "{o}/u.tif"], 1, ("given twice",)),
    ("crosstalk-grid-without-sweep", ["crosstalk", "{i}/biased.tif", "--grid",
                                      "{i}/rt/grid.yaml", "-o", "{o}/c.json"], 2,
     ("--grid applies to the --mask-widths sweep only",)),
    # a mask as wide as the micro-images keeps none of them: the range it can take is named
    ("crosstalk-mask-widths-past-the-pitch", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                              "{i}/rt/grid.yaml", "--mask-widths", "0,1e308",
                                              "--tile", "8", "-o", "{o}/c.json"], 2,
     ("--mask-widths", "0 <= m < ")),
    ("crosstalk-mask-widths-infinite", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                        "{i}/rt/grid.yaml", "--mask-widths", "0,inf", "-o",
                                        "{o}/c.json"], 2, ("'--mask-widths'", ">= 0 px")),
    # audit 9 E8: the sweep wrote no preview and said nothing
    ("crosstalk-mask-widths-preview", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                       "{i}/rt/grid.yaml", "--mask-widths", "0,1", "-o",
                                       "{o}/c.json", "--preview", "{o}/c.png"], 2,
     ("--preview is not drawn for the --mask-widths sweep",)),
    ("crosstalk-mask-widths-twice", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                     "{i}/rt/grid.yaml", "--mask-widths", "0,1,1", "-o",
                                     "{o}/c.json"], 2, ("'--mask-widths'", "each once")),
    # optics
    ("optics-png", ["optics", "{i}/huge.png"], 1, ("not a YAML lens",)),
    ("optics-prism-n-1", ["optics", "{l}", "--prism-n", "1"], 2, ("'--prism-n'",)),
    ("optics-prism-n-huge", ["optics", "{l}", "--prism-n", "1e9"], 2, ("'--prism-n'",)),
    ("optics-prism-reflects", ["optics", "{l}", "--prism-apex-deg", "89.9"], 1,
     ("totally",)),
    ("optics-sensor-beyond-image-circle", ["optics", "{l}", "--sensor-mm", "20"], 1,
     ("image circle",)),
    ("optics-pixel-huge", ["optics", "{l}", "--crosstalk", "--pixel-um", "1e9"], 2,
     ("'--pixel-um'",)),
    ("optics-pixel-tiny", ["optics", "{l}", "--crosstalk", "--pixel-um", "1e-9"], 2,
     ("'--pixel-um'",)),
    # simulate
    # audit 7 E11: a value simulate does not take is a usage error (exit 2), as for a flag
    ("simulate-pixels-0", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "0"], 2,
     ("'0' is not one positive whole number",)),
    ("simulate-pixels-huge", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "1000000"], 2,
     ("smaller sensor",)),
    ("simulate-rays-huge", ["simulate", "quadpixel-white", "-o", "{o}/s", "--pixels", "64",
                            "--rays", "100000000"], 2, ("smaller sensor",)),
    ("simulate-rows-x-cols-for-one-number", ["simulate", "dualpixel-white", "-o", "{o}/s",
                                             "--pixels", "64x96"], 2, ("pixels = '64x96'",)),
    ("simulate-param-nan", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param",
                            "pitch_px=.nan"], 2, ("pitch_px = nan",)),
    ("simulate-param-text", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param", "size=abc"],
     2, ("size = 'abc'",)),
    ("simulate-pixels-tiny", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "2"], 2,
     ("at least 16",)),
    ("simulate-pitch-negative", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param",
                                 "pitch_px=-3"], 2, ("pitch_px must be",)),
    ("simulate-rig-empty-views", ["simulate", "stereo-rig", "-o", "{o}/s", "--param",
                                  "view_shape=[0, 0]"], 2, ("view_shape must be",)),
    ("simulate-raytrix-s-0", ["simulate", "raytrix-scene", "-o", "{o}/s", "--param", "s=0"], 2,
     ("s must be",)),
    ("simulate-raytrix-g-negative", ["simulate", "raytrix-scene", "-o", "{o}/s", "--param",
                                     "g_true=-1"], 2, ("g_true must be > 0",)),
    ("simulate-noise-negative", ["simulate", "dualpixel", "-o", "{o}/s", "--param", "noise=-5"],
     2, ("noise must be in [0, 65535]", "got -5")),
    ("simulate-crosstalk-one", ["simulate", "dualpixel-prism", "-o", "{o}/s", "--pixels", "48",
                                "--param", "crosstalk=1"], 2, ("crosstalk must be in [0, 1)",)),
    ("simulate-param-unknown", ["simulate", "dualpixel", "-o", "{o}/s", "--param", "nosie=1"],
     2, ("does not take 'nosie'", "noise")),
    ("bias-crop-below-cfa-cell", ["bias", "{i}/frames.tif", "--crop", "1x1", "-o", "{o}/b.tif"],
     1, ("CFA cell",)),
    ("develop-wb-huge", ["develop", "{i}/biased.tif", "--view", "S", "--wb", "1e308,1,1", "-o",
                         "{o}/d.jpg"], 2, ("100 times",)),
    ("develop-output-webp", ["develop", "{i}/biased.tif", "--view", "S", "-o", "{o}/d.webp"],
     2, ("'-o' / '--output'", "an 8-bit JPEG or PNG", ".tiff, .jpg, .jpeg or .png")),
    # audit 10 E5: a clash of two options known before reading, as --quality with a .tif is
    ("develop-rec2020-linear-jpeg", ["develop", "{i}/biased.tif", "--view", "S", "--space",
                                     "rec2020-linear", "-o", "{o}/d.jpg"], 2,
     ("--space rec2020-linear needs 16 bits", "-o NAME.tif")),
    ("develop-wb-from-other-views", ["develop", "{i}/biased.tif", "--view", "S", "--matrix",
                                     "none", "--wb-from", "{i}/white_xy.tif", "-o",
                                     "{o}/d.jpg"], 1, ("no view S",)),
    # audit 12 E: develop's photograph was "a plain (not plenocli) TIFF: decode it first"
    # (decode refuses it), its JPEG "not a readable TIFF"
    *[(f"develop-own-photograph-{ext}", ["develop", f"{{i}}/photo.{ext}", "-o", "{o}/d.jpg"], 1,
       ("`plenocli develop` photograph", "biased.tif), or", "develop --linear"))
      for ext in ("tif", "jpg")],
    # audit 12 W: develop's linear TIFF is white-balanced already
    ("develop-linear-wb-from", ["develop", "{i}/linear.tif", "--wb-from", "{i}/biased.tif",
                                "-o", "{o}/d.jpg"], 1, ("white-balanced already", "--wb R,G,B")),
    # audit 15 E1: --recover-highlights on view A changed nothing and recorded rebuilt pixels
    ("develop-recover-view-a", ["develop", "{i}/biased.tif", "--view", "A",
                                "--recover-highlights", "{i}/biased_copy.tif", "-o",
                                "{o}/d.jpg"], 2,
     ("view A is what it reads", "--view S or B")),
    ("develop-linear-recover", ["develop", "{i}/linear.tif", "--recover-highlights",
                                "{i}/biased.tif", "-o", "{o}/d.jpg"], 1,
     ("linear TIFF (R, G, B pages)", "when developing the views it came from")),
    # batch
    ("batch-timeout-0", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "--timeout", "0"],
     2, ("'--timeout'", "x>0")),
    ("batch-timeout-nan", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "--timeout",
                           "nan"], 2, ("'--timeout'", "not a finite number")),
    ("batch-jobs-with-scheduler", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                   "--scheduler", "tcp://127.0.0.1:1", "-j", "2"], 2,
     ("-j/--jobs", "leave -j out")),
    # audit 21 M3: click's "'2.0' is not a valid integer range" where every other whole number
    # option says how to write it
    ("batch-jobs-decimal", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "-j", "2.0"], 2,
     ("'-j' / '--jobs'", "'2.0' is not a valid integer (a whole number is written in digits: 2)")),
    ("batch-jobs-zero", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "-j", "0"], 2,
     ("'-j' / '--jobs'", "0 is not in the range x>=1")),
    ("batch-timeout-with-scheduler", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                      "--scheduler", "tcp://127.0.0.1:1", "--timeout", "5"], 2,
     ("--timeout limits local worker processes",)),
    # audit 20 E1: 1e7 s and up were exit 1, "give a positive number of seconds"
    ("batch-timeout-huge", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "--timeout",
                            "1e7"], 2, ("'--timeout'", "x<1e+07")),
    ("batch-scheduler-malformed", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                   "--scheduler", "nonsense"], 1, ("tcp://HOST:PORT",)),
    ("batch-scheduler-not-there", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                   "--scheduler", "tcp://127.0.0.1:1"], 1, ("cannot reach",)),
    ("batch-inputs-none", ["batch", "{i}/none.yaml", "--inputs", "{i}/nothing/*.dng"], 1,
     ("matches no file",)),
    ("unmix-regularise-huge", ["unmix", "{i}/qg/views.tif", "--mixing", "{i}/qg/mixing.tif",
                               "--regularise", "1e308", "-o", "{o}/u.tif"], 2,
     ("'--regularise'",)),
    # info
    ("info-zlib-truncated", ["info", "{i}/zlib_trunc.tif"], 1, ("truncated",)),
    ("info-garbage", ["info", "{i}/garbage.tif"], 1, ("damaged",)),
    ("info-huge-png", ["info", "{i}/huge.png"], 1, ("more than",)),
    ("info-bad-xml", ["info", "{i}/calib_basis_zero.xml"], 1, ("lens_base",)),
    ("info-bad-yaml", ["info", "{i}/not_yaml.yaml"], 1, ("YAML",)),
    ("info-truncated", ["info", "{i}/truncated.tif"], 1, ("truncated",)),
    ("info-huge-header", ["info", "{i}/huge.tif"], 1, ("200000",)),
    ("info-empty", ["info", "{i}/empty.tif"], 1, ("empty.tif", "does not know this kind")),
    # every reader: a damaged TIFF is one line
    ("sai-truncated", ["sai", "{i}/truncated.tif", "-o", "{o}/v.tif"], 1, ("truncated",)),
    ("refocus-huge", ["refocus", "{i}/huge.tif", "--grid", "{i}/rt/grid.yaml", "-o",
                      "{o}/r.tif"], 1, ("200000",)),
    ("bias-device", ["bias", "/dev/null", "-o", "{o}/b.tif"], 1, ("not a regular file",)),
    ("info-device", ["info", "/dev/zero"], 1, ("not a regular file",)),
    ("decode-folder-as-calib", ["decode", "{i}/f512.tif", "--camera", "raytrix", "--calib",
                                "{i}/rt", "-o", "{o}/d.tif"], 2, ("directory",)),
    ("bias-complex", ["bias", "{i}/complex.tif", "-o", "{o}/b.tif"], 1, ("real",)),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_leaves_nothing(case, inputs, tmp_path):
    name, args, code, words = case
    if "views.tif" in " ".join(args):
        result = CliRunner().invoke(cli, ["sai", str(inputs / "f512.tif"), "-o",
                                          str(tmp_path / "views.tif")])
        assert result.exit_code == 0, result.output
    if "clipped_frames" in " ".join(args):
        result = CliRunner().invoke(cli, ["decode", str(inputs / "clipped.dng"), "-o",
                                          str(tmp_path / "clipped_frames.tif")])
        assert result.exit_code == 0, result.output
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, code, words)


@pytest.mark.parametrize("head", [b"II*\0", b"MM\0*", b"II*\0\x08\0\0", b"II+\0\x08\0\0\0"])
@pytest.mark.parametrize("command", [["info"], ["info", "--json"], ["decode", "-o", "{o}/d.tif"],
                                     ["decode", "--camera", "dng", "-o", "{o}/d.tif"],
                                     ["bias", "-o", "{o}/b.tif"], ["sai", "-o", "{o}/s.tif"],
                                     ["calibrate", "-o", "{o}/g.yaml"]])
def test_a_tiff_cut_inside_its_header_is_damaged_not_an_internal_error(head, command, tmp_path):
    # audit 7 I1: tifffile's struct.error ("unpack requires a buffer of 4 bytes") was an
    # internal error in every command
    cut = tmp_path / "in" / "cut.tif"
    cut.parent.mkdir()
    cut.write_bytes(head)
    result = run_bad(tmp_path / "in", tmp_path / "out", [command[0], str(cut), *command[1:]])
    assert_one_line(result, 1, ("damaged TIFF", "ends inside its header", "truncated"))


def test_truncated_tiff_gives_no_stray_tifffile_line(inputs, tmp_path, capfd):
    result = run_bad(inputs, tmp_path / "out", ["info", "{i}/truncated.tif"])
    captured = capfd.readouterr()
    assert "tifffile" not in captured.err + captured.out + result.stderr
    assert_one_line(result, 1, ("truncated",))


@pytest.mark.parametrize("args", [
    ["decode", "{f}", "-o", "{o}/d.tif"], ["decode", "--camera", "dng", "{f}", "-o", "{o}/d.tif"],
    ["bias", "{f}", "-o", "{o}/b.tif"], ["develop", "{f}", "-o", "{o}/p.jpg"],
    ["sai", "{f}", "-n", "2", "-o", "{o}/v.tif"], ["calibrate", "{f}", "-o", "{o}/g.yaml"],
    ["flat", "{i}/f512.tif", "--white", "{f}", "-o", "{o}/f.tif"],
])
def test_a_pipe_as_input_is_refused_without_waiting_for_a_writer(args, inputs, tmp_path):
    """audit 18 U1: every stage opened a named pipe (to judge its kind) before its reader's
    check, and waited for a writer for ever. A writer comes after 5 s here, so a regression
    fails instead of hanging the suite."""
    import os
    import threading

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)

    def unblock():
        if not done.wait(5):
            waited.append(True)
            with open(fifo, "wb"):
                pass
    done, waited = threading.Event(), []
    threading.Thread(target=unblock, daemon=True).start()
    words = [a.replace("{f}", str(fifo)) for a in args]
    result = run_bad(inputs, tmp_path / "out", words)
    done.set()
    assert not waited, "the command opened the pipe and waited for a writer"
    assert_one_line(result, 1, ("not a regular file",))


@pytest.mark.parametrize("mode", [[], ["--dry-run"], ["--print-make"]])
def test_a_pipe_as_a_step_input_is_refused_by_the_plan(mode, inputs, tmp_path):
    """audit 18 U1 through run: the plan judged the pipe's kind by opening it (--dry-run too)."""
    import os

    fifo = tmp_path / "pipe.dng"
    os.mkfifo(fifo)
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  decode: {{input: {fifo}, output: {tmp_path}/o/f.tif}}\n")
    result = run_bad(inputs, tmp_path / "o", ["run", str(config), *mode])
    assert_one_line(result, 1, ("step 'decode'", "not a regular file"))
