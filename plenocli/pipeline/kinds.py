"""Which kind of file each stage takes for each input role, read from the producing stage.

Every plenocli TIFF records the stage that made it (``provenance.stage``, and the stages
before it in ``history``), so a stage can refuse a file of the wrong kind (a depth map as
views, a gain map as a white) or one it has already processed (unmix of an unmixed file,
flat of a flat-fielded one): both would give a wrong result with exit 0. decode takes no
plenocli file at all (frames, views, photographs and previews are not raws: decoding one again
drops its history and its levels), and only decode takes a raw capture (DNG, CR2). Other
foreign files (no plenocli record) are accepted as they are: their reader checks what it can.
The other roles (a grid, a saved gain or transform, a rig) take what one stage's option writes
(SIDE_INPUTS): a plenocli output of another role is refused, named as what it is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from plenocli.errors import InputError
from plenocli.pipeline.validators import TIFF

# frames or views of one capture, as decode, bias, flat and unmix leave them (and the simulator)
CAPTURE = ("decode", "bias", "flat", "unmix", "simulate")
# views of a capture: also the SAIs sai cuts and the (stereo) views refocus renders
VIEWS = (*CAPTURE, "sai", "refocus")
PICTURES = (*VIEWS, "stitch", "develop")

# stage -> input role -> the producing stages it accepts
ACCEPTS: dict[str, dict[str, tuple[str, ...]]] = {
    "decode": {"input": ()},
    "bias": {"input": ("decode",)},
    "flat": {"input": CAPTURE, "white": ("decode", "bias", "simulate")},   # --gain: flat's own
    "unmix": {"inputs": VIEWS, "mixing": ("crosstalk", "simulate")},
    "crosstalk": {"inputs": VIEWS},
    "calibrate": {"input": CAPTURE},
    "sai": {"input": CAPTURE},
    "refocus": {"input": CAPTURE, "depth": ("depth",)},
    "depth": {"input": (*CAPTURE, "sai")},
    "develop": {"input": PICTURES, "wb_from": VIEWS, "recover_highlights": CAPTURE},
    "stitch": {"inputs": VIEWS},
}
# the maps stages write beside their result (their own stage names): never light levels
MAPS = {"flat-gain": "a gain map, not an image",
        "unmix-noise-gain": "a noise-gain map, not views"}
# the command that writes an output recorded under another stage name
COMMANDS = {"flat-gain": "flat --save-gain", "unmix-noise-gain": "unmix --noise-map"}
# the option that writes a stage's image where -o does not (crosstalk's -o is a JSON report;
# develop's -o a photograph, refused past develop): its record names the stage only
IMAGE_OPTION = {"crosstalk": "mixing_out", "develop": "linear"}
# the other input roles: stage -> role -> (the outputs that make such a file, as (stage,
# output role); what it is, in words). A plenocli output of another role is refused here,
# before any step runs; a foreign file is its reader's to check.
GRIDS = (("calibrate", "output"), ("calibrate", "xml"), ("simulate", "grid"),
         ("simulate", "xml"))
GRID = "a lens grid (the YAML or --xml of calibrate, or a Raytrix RayCalibData XML)"
SIDE_INPUTS: dict[str, dict[str, tuple[tuple[tuple[str, str], ...], str]]] = {
    "decode": {"calib": ((("calibrate", "xml"), ("simulate", "xml")),
                         "a Raytrix RayCalibData XML (or the one calibrate --xml writes)")},
    "flat": {"gain": ((("flat", "save_gain"),), "the gain map flat --save-gain writes")},
    "calibrate": {"start": (GRIDS, GRID), "compare": (GRIDS, GRID)},
    "refocus": {"grid": (GRIDS, GRID)},
    "depth": {"grid": (GRIDS, GRID), "camera": ((), "a camera YAML (focal_length_mm, "
                                                    "focus_distance_m, mla_sensor_mm)")},
    "sai": {"grid": (GRIDS, GRID)},
    "crosstalk": {"grid": (GRIDS, GRID)},
    "stitch": {"rig": ((("stitch", "report"),), "a prism rig YAML (configs/rigs/), or the "
                       "--report of a stitch with --rig (it holds the rig it used); a "
                       "--transform-out goes to --transform-in"),
               "transform_in": ((("stitch", "transform_out"), ("stitch", "report")),
                                "the JSON transform stitch --transform-out writes (or its "
                                "--report)")},
    "optics": {"input": ((), "a lens prescription YAML")},
}
# side roles that a main input of one kind leaves without meaning:
# (stage, what made its input) -> role -> why, after "INPUT"
EXCLUDED = {("develop", ("develop", "linear")): {
    "wb_from": "is develop's linear TIFF, white-balanced already, and a white image measures "
               "the camera's gains: give --wb R,G,B for a correction on top, or develop the "
               "views it came from",
    "recover_highlights": "is develop's linear TIFF (R, G, B pages): it holds no dual-pixel "
                          "A, B, S views; give --recover-highlights when developing the views "
                          "it came from"}}
PHOTOS = (".png", ".jpg", ".jpeg")
# (stage, role) whose reader needs what only the producer records (bias: decode's areas and
# levels; unmix's mixing: the matrix crosstalk --mixing-out records): no foreign file
RECORD_NEEDED = (("bias", "input"), ("unmix", "mixing"))
# stages a capture goes through once: applied again they correct what is already corrected
ONCE = ("bias", "flat", "unmix")


@dataclass(frozen=True)
class Planned:
    """What an earlier step of a run will have written at a path, known before it runs: the
    stages that made it (oldest first), or what else it is."""

    made: tuple[str, ...] = ()
    photograph: str | None = None   # develop's photograph: the views it was developed from
    document: str | None = None     # not an image: what it is
    raw: bool = False               # a raw capture (simulate writes one)
    wrote: tuple[str, str] | None = None  # (stage, output role) writing it; None: not known


def check_kinds(stage: str, inputs: Mapping[str, Sequence[Path]],
                planned: Mapping[Path, Planned | None] | None = None) -> None:
    """InputError for the first input whose recorded producer ``stage`` does not take in its
    role, or that already went through ``stage`` (one of ONCE). ``planned``: the files earlier
    steps of a run will write (absolute paths; None: not known), taken as what they will be."""
    for role, accepted in ACCEPTS.get(stage, {}).items():
        for path in inputs.get(role, ()):
            plan = _planned(path, planned or {})
            if plan is None and _not_known(path, planned or {}):
                continue  # another run or step makes it, as what: its stage checks it then
            if plan is not None and (plan.document or (plan.raw and stage != "decode")):
                raise InputError(_planned_not_an_image(path, plan, stage, role))
            if plan is not None and plan.raw:
                continue  # decode takes it
            made = list(plan.made) if plan is not None else made_by(path)
            if not made and plan is None:
                _check_not_a_document(path, stage, role)
            if not made and plan is None and stage != "decode":
                _check_not_raw(path, stage, role)
            if not made or made[-1] is None:
                continue
            if not accepted:
                raise InputError(_not_a_raw(path, made))
            if made[-1] not in accepted:
                wrote = plan.wrote if plan is not None else _wrote(path, planned or {})
                raise InputError(f"{path} is {_output_name(wrote)}; {_takes(stage, role)}")
            if made[-1] == "develop" and (plan.photograph if plan is not None
                                          else _photograph(path)):
                raise InputError(_photograph_refused(path, stage, role,
                                                     plan.photograph if plan else None))
            if stage in ONCE and role in ("input", "inputs") and stage in made:
                raise InputError(f"{path} already went through `plenocli {stage}`; applying "
                                 "it twice corrects what is already corrected: give the file "
                                 "from before it")
    _check_side_inputs(stage, inputs, planned or {})


def _check_side_inputs(stage: str, inputs: Mapping[str, Sequence[Path]],
                       planned: Mapping[Path, Planned | None]) -> None:
    """The roles beyond ACCEPTS (grids, gains, transforms, rigs): a plenocli output (or what
    an earlier step will write) of a role other than one that makes such a file is refused;
    so is a side file that the main input leaves without meaning (EXCLUDED)."""
    for role, (makers, takes) in SIDE_INPUTS.get(stage, {}).items():
        for path in inputs.get(role, ()):
            wrote = _wrote(path, planned)
            if wrote is not None and wrote not in makers:
                raise InputError(f"{path} is {_output_name(wrote)}; {stage} takes as "
                                 f"{_label(role)} {takes}")
            on_disk = _planned(path, planned) is None and not _not_known(path, planned)
            made = _document_stage(path) if wrote is None and on_disk else None
            # the stage's own documents are its reader's to tell apart (a stitch report given
            # as --rig holds the rig it used; a transform there is named as one)
            if made is not None and made != stage and made not in (m for m, _ in makers):
                raise InputError(f"{path} is a JSON document `plenocli {made}` writes; "
                                 f"{stage} takes as {_label(role)} {takes}")
    main = (inputs.get("input") or [None])[0]
    excluded = EXCLUDED.get((stage, _wrote(main, planned))) if main is not None else None
    for role, why in (excluded or {}).items():
        for side in inputs.get(role, ()):
            raise InputError(f"--{_label(role)} {side}: {main} {why}")


def _wrote(path: Path, planned: Mapping[Path, Planned | None]) -> tuple[str, str] | None:
    """(stage, output role) of the plenocli output at ``path``, or of what an earlier step
    will write there; None when not known (a foreign file, a file inside a folder output)."""
    plan = _planned(path, planned)
    if plan is not None or _not_known(path, planned):
        return plan.wrote if plan is not None else None
    made = made_by(path)
    if not made or made[-1] is None:
        return _simulated_document(path)
    if made[-1] == "preview":
        return ("", "preview")
    if made[-1] == "develop":
        return ("develop", "output" if _photograph(path) else "linear")
    return RECORDED_AS.get(made[-1], (made[-1], IMAGE_OPTION.get(made[-1], "output")))


def _takes(stage: str, role: str) -> str:
    """What ``stage`` takes in an image role, by the commands (and options) writing it."""
    foreign = "" if (stage, role) in RECORD_NEEDED else " (or a foreign file)"
    once = stage in ONCE and role in ("input", "inputs")  # its own output is refused
    producers = [p for p in ACCEPTS[stage][role] if not (once and p == stage)]
    return (f"{stage} takes as {_label(role)} the output of "
            f"{', '.join(map(_producer, producers))}{foreign}")


def _producer(name: str) -> str:
    """The command (and option) writing the images a record names ``name``."""
    if name in IMAGE_OPTION:
        return f"{name} --{_label(IMAGE_OPTION[name])}"
    return COMMANDS.get(name, name)


def _simulated_document(path: Path) -> tuple[str, str] | None:
    """("simulate", "truth") for a simulate step's truth.json already written (its record is
    its provenance); None for any other file (its reader checks it)."""
    return ("simulate", "truth") if _document_stage(path) == "simulate" else None


def _document_stage(path: Path) -> str | None:
    """The stage recorded in a plenocli JSON document's provenance (a report, a transform,
    simulate's truth); None for any other file (its reader checks it)."""
    from plenocli.io.yamlfile import DocumentError, read_json

    if Path(path).suffix.lower() != ".json" or not Path(path).is_file():
        return None
    try:
        with open(path, "rb") as f:
            if f.read(1) != b"{":
                return None
        doc = read_json(path)  # at most its reader's size, like every document
    except (OSError, DocumentError):
        return None
    record = doc.get("provenance") if isinstance(doc, dict) else None
    stage = record.get("stage") if isinstance(record, dict) else None
    return stage if isinstance(stage, str) and stage.isidentifier() else None


def _output_name(wrote: tuple[str, str]) -> str:
    """How a message names what a stage wrote in one of its output roles."""
    stage, role = wrote
    if stage == "simulate" and role in SIMULATED_ROLES:
        return SIMULATED_ROLES[role]
    if role == "preview":
        return "a plenocli preview (display-stretched 8-bit levels)"
    if wrote == ("develop", "output"):
        return "a `plenocli develop` photograph (display-encoded levels, not light)"
    option = "" if role == "output" else f" --{_label(role)}"
    what = MAPS.get(SIDE_OUTPUTS.get(wrote, ("",))[0])
    return f"a `plenocli {stage}{option}` output{f' ({what})' if what else ''}"


def _label(role: str) -> str:
    return role.replace("_", "-")


def _photograph(path: Path) -> bool:
    """develop's photograph (JPEG, PNG, 16-bit TIFF), not its --linear TIFF: the photograph's
    levels are display-encoded (a tone curve, clipped to white), its linear TIFF's are light."""
    from plenocli.io import tiffio

    if Path(path).suffix.lower() in PHOTOS:
        return True
    try:
        return not tiffio.read_meta(path)  # the linear TIFF carries plenocli metadata
    except InputError:
        return True


def _photograph_refused(path: Path, stage: str, role: str, source: str | None = None) -> str:
    from plenocli.io.photo import photo_record

    if source is None:
        record = (photo_record(path) or {}).get("plenocli") or {}
        source = next((i.get("path") for i in record.get("inputs") or []
                       if isinstance(i, dict) and i.get("role") == "input"), None)
    came = f" ({source})" if source else ""
    return (f"{path} is a `plenocli develop` photograph (display-encoded levels, not light); "
            f"{stage} takes as {_label(role)} the views it was developed from{came}, "
            "or the scene-referred TIFF `develop --linear` writes")


def _check_not_raw(path: Path, stage: str, role: str) -> None:
    """A raw capture (DNG, CR2) holds no views or frames a stage after decode reads: its
    pages are the sensor's data as stored, margins and black level included."""
    from plenocli.io import raw as raw_io

    if not Path(path).is_file():
        return  # a pipe would block the open; the stage's reader says what it is
    try:
        kind = raw_io.sniff(path)
    except (InputError, OSError):
        return  # the stage's reader says what is wrong with it
    if kind in ("canon-dp", "dng"):
        name = "DNG" if kind == "dng" else "Canon dual-pixel CR2"
        raise InputError(f"{path} is a raw capture ({name}), not the decoded frames or views "
                         f"{stage} takes as {_label(role)}: decode it first "
                         f"(plenocli decode{'' if stage == 'bias' else ', then plenocli bias'})")


# text documents plenocli reads or writes beside its images, told by their first bytes
DOCUMENT_SUFFIXES = (".yaml", ".yml", ".json", ".xml")
DOCUMENTS = ((b"<RayCalibData", "a Raytrix RayCalibData XML (a camera calibration: it goes "
                                "with --grid, calibrate's --start or decode's --calib)"),
             (b"lens_grid:", "a plenocli lens grid (it goes with --grid, or calibrate's --start)"),
             (b"steps:", "a pipeline config (plenocli run CONFIG runs it)"),
             (b"surfaces:", "a lens prescription (plenocli optics LENS reads it)"))


def _check_not_a_document(path: Path, stage: str, role: str) -> None:
    """A grid, config, report or calibration given where an image goes is named, not called a
    damaged image."""
    suffix = Path(path).suffix.lower()
    if not Path(path).is_file():
        return  # a pipe would block the open; the stage's reader says what it is
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return  # the stage's reader says what is wrong with it
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if b"\0" in head or not (suffix in DOCUMENT_SUFFIXES or text[:1] in (b"{", b"<")):
        return
    what = next((name for mark, name in DOCUMENTS if mark in head), None)
    made = _document_stage(path) if what is None else None
    if made is not None:  # a report, a transform: its producer, not its role, is recorded
        what = (SIMULATED_ROLES["truth"] if made == "simulate"
                else f"a JSON document `plenocli {made}` writes")
    if what is None:
        what = ("a JSON document (a report, transform or record)" if text[:1] in (b"{", b"[")
                else "an XML document" if text[:1] == b"<" else "a text document")
    raise InputError(f"{path} is {what}, not an image {stage} can take as "
                     f"{_label(role)}; {_takes(stage, role)}" if stage != "decode" else
                     f"{path} is {what}, not a raw capture or sensor image")


def made_by(path: Path) -> list:
    """The stages that made ``path``, oldest first, from its plenocli record (a TIFF's
    metadata, a photograph's description, a preview's tag); [] for a foreign or unreadable
    file (its reader says what is wrong with it)."""
    from plenocli.io import tiffio
    from plenocli.io.photo import photo_record
    from plenocli.io.preview import is_preview

    suffix = Path(path).suffix.lower()
    if suffix not in (*TIFF, *PHOTOS) or not Path(path).is_file():
        return []
    meta = {}
    if suffix in TIFF:
        try:
            meta = tiffio.read_meta(path)
        except InputError:
            return []
    if not meta:
        meta = photo_record(path) or {}
        meta = {"history": meta.get("history"), "provenance": meta.get("plenocli")}
    if suffix == ".png" and is_preview(path):
        return ["preview"]
    return [r.get("stage") for r in (*(meta.get("history") or []), meta.get("provenance") or {})
            if isinstance(r, dict)]


def _not_a_raw(path: Path, made: list) -> str:
    """Why decode refuses a file plenocli made, and where it goes instead."""
    stage = made[-1]
    if stage == "preview":
        return (f"{path} is a plenocli preview (display-stretched 8-bit levels), not a sensor "
                "image: decode the capture it shows")
    if stage == "develop":
        return (f"{path} is a `plenocli develop` output (a photograph, or its scene-referred "
                "linear TIFF), not a raw capture or sensor image: decode the capture it came "
                "from")
    takers = _takers(path, stage, made)
    where = (f"give it as it is to {', '.join(takers)}" if takers
             else "no stage reads it as an image; decode the capture it came from")
    return (f"{path} is a `plenocli {_producer(stage)}` output, not a raw capture "
            "or sensor image "
            f"(decoding it again would drop its record and levels): {where}")


# stages that read lenslet frames (micro-images), not views cut from them
FRAMES_ONLY = ("calibrate", "sai", "refocus")


def _takers(path: Path, stage: str, made: list) -> list[str]:
    """The stages (with the option, for a side input) that take this output of ``stage`` as
    it is: not one it went through already, not a frames reader for views, not depth for
    colour views, and none for what every taker refuses (a focal sweep, a disparity map)."""
    from plenocli.io import tiffio
    from plenocli.model.views import split_colour_page, split_sweep

    try:
        names = [str(n) for n in tiffio.read_meta(path).get("views") or []]
    except InputError:
        names = []
    if any(split_sweep(n)[1] for n in names):
        return []  # one view at several g: refocus each view at one g instead
    if stage == "depth":
        return ["refocus --depth"] if names[:1] == ["g"] else []
    views_only = "sai" in made or stage in ("sai", "refocus")
    colour = any(split_colour_page(n) for n in names)  # depth measures grey views only
    takers = []
    for name, roles in ACCEPTS.items():
        if name in made or (views_only and name in FRAMES_ONLY) or (colour and name == "depth"):
            continue
        for role, accepted in roles.items():
            if stage in accepted:
                takers.append(name if role in ("input", "inputs")
                              else f"{name} --{_label(role)}")
                break
    kind = RECORDED_AS.get(stage, (stage, "output"))
    return takers + [f"{name} --{_label(role)}" for name, roles in SIDE_INPUTS.items()
                     for role, (makers, _) in roles.items() if kind in makers]


# outputs recorded under another stage name than their step's, and the input role whose
# history they carry (the others carry the history of the step's main input)
SIDE_OUTPUTS = {("flat", "save_gain"): ("flat-gain", "white"),
                ("unmix", "noise_map"): ("unmix-noise-gain", "inputs")}
RECORDED_AS = {name: wrote for wrote, (name, _) in SIDE_OUTPUTS.items()}
RAW_SUFFIXES = (".dng", ".cr2")
# what simulate writes into its folder beside its images, told by suffix (its kinds write one
# file of each: truth.json, truth.npz, grid.yaml, grid_true.xml; raws): the role each plays
SIMULATED = {".json": "truth", ".npz": "truth_arrays", ".yaml": "grid", ".xml": "xml",
             **dict.fromkeys(RAW_SUFFIXES, "raw")}
SIMULATED_ROLES = {
    "truth": "the ground truth `plenocli simulate` writes (truth.json)",
    "truth_arrays": "the ground-truth arrays `plenocli simulate` writes (truth.npz)",
    "grid": "the true lens grid `plenocli simulate` writes (grid.yaml)",
    "xml": "the true lens grid `plenocli simulate` writes as a Raytrix RayCalibData XML",
    "raw": "a raw capture `plenocli simulate` writes"}


def planned_outputs(stage: str, outputs: Mapping[str, Sequence[Path]],
                    inputs: Mapping[str, Sequence[Path]],
                    planned: Mapping[Path, Planned | None]) -> dict[Path, Planned | None]:
    """What a step of ``stage`` will write, by absolute path, for the steps after it
    (:func:`check_kinds`); a folder output (simulate's) maps to Planned(made=(stage,))."""
    def history(role: str) -> tuple[str, ...] | None:
        paths = inputs.get(role) or inputs.get("inputs") or ()
        if not paths or stage == "decode":
            return ()  # decode takes no plenocli file: its frames start a history
        plan = _planned(paths[0], planned)
        if plan is None and _not_known(paths[0], planned):
            return None
        return plan.made if plan is not None else tuple(made_by(paths[0]))

    out: dict[Path, Planned | None] = {}
    for role, paths in outputs.items():
        name, source = SIDE_OUTPUTS.get((stage, role), (stage, "input"))
        before = history(source)
        for path in paths:
            key, suffix = Path(path).absolute(), Path(path).suffix.lower()
            wrote = (stage, role)
            if suffix in DOCUMENT_SUFFIXES:
                out[key] = Planned(document=f"a {suffix[1:].upper()} document step {stage} "
                                            "writes", wrote=wrote)
            elif suffix in PHOTOS and role == "preview":
                out[key] = Planned(made=("preview",), wrote=wrote)
            elif before is None:
                out[key] = None
            elif stage == "develop" and role == "output":
                source_path = (inputs.get("input") or [None])[0]
                out[key] = Planned(made=(*before, name), photograph=str(source_path),
                                   wrote=wrote)
            else:
                out[key] = Planned(made=(*before, name), wrote=wrote)
    return out


def _planned(path: Path, planned: Mapping[Path, Planned | None]) -> Planned | None:
    """The plan for ``path``: its own, or a file inside a planned folder (simulate's)."""
    key = Path(path).absolute()
    if key in planned:
        return planned[key]
    folder = next((planned[p] for p in key.parents if p in planned), None)
    if folder is None:
        return None
    suffix = key.suffix.lower()
    if suffix in SIMULATED:  # only simulate writes a folder
        role = SIMULATED[suffix]
        return Planned(raw=role == "raw", document=None if role == "raw" else
                       SIMULATED_ROLES[role], wrote=("simulate", role))
    if suffix in DOCUMENT_SUFFIXES:
        return Planned(document=f"a {suffix[1:].upper()} document (not an image)")
    # simulate writes plenocli TIFFs and plain sensor TIFFs (decode's), told apart only by
    # what each kind makes when it runs
    return None


def _not_known(path: Path, planned: Mapping[Path, Planned | None]) -> bool:
    """Whether a step writes ``path`` without its kind being known before it runs (an output
    of another run; an image inside a folder a step fills): its stage checks it then."""
    key = Path(path).absolute()
    return key in planned or (_planned(path, planned) is None
                              and any(p in planned for p in key.parents))


def _planned_not_an_image(path: Path, plan: Planned, stage: str, role: str) -> str:
    if plan.raw:
        return (f"{path} is a raw capture, not the decoded frames or views {stage} takes as "
                f"{_label(role)}: decode it first")
    return (f"{path} is {plan.document}, not an image {stage} can take as "
            f"{_label(role)}; {_takes(stage, role)}" if stage != "decode" else
            f"{path} is {plan.document}, not a raw capture or sensor image")
