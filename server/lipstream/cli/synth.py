"""``lipstream synth``: frames of a phones file, a text (espeak-ng) or a TTS timing file,
written in an export format, through an output profile when one is given."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from lipstream_client.messages import NAMINGS, VISEME_SETS

from ..config import Settings, demo_model_path
from ..errors import LipstreamError
from ..exports import FORMATS, MOHO_FPS
from ..frontends.timings import TIMING_FORMATS
from ..timeline import EMOTIONS

if TYPE_CHECKING:
    from lipstream_client import OutputProfile

    from ..audio import Audio
    from ..timeline import PhonemeSpan
    from .commands import Commands


def _synth(args: argparse.Namespace, settings: Settings) -> None:
    from ..audio import read_wav, write_wav
    from ..engines import load_model
    from ..exports import SHAPE_FORMATS, format_for
    from ..exports.writer import ExportSettings
    from ..output.profiles import apply_to_result
    from ..phones_io import read_phones, write_frames

    out = Path(args.out)
    format_name = format_for(out, args.format)
    profile = _output_profile(args, shapes=format_name in SHAPE_FORMATS)
    model_dir = Path(args.model) if args.model else demo_model_path(args.engine, settings)
    model = load_model(model_dir)
    sound_file = args.audio or ""
    audio: Audio | None
    if args.words is not None:
        spans = _word_timing_spans(args, model_dir)
        audio = read_wav(Path(args.audio)) if args.audio else None
    elif args.transcript is not None:
        spans, audio = _aligned_spans(args)
    elif args.text is not None:
        from ..speech.text_frontend import speak_text

        _check_text_options(args)
        spoken = speak_text(args.text, args.voice, args.rate, lang=args.lang)
        spans, audio = spoken.spans, spoken.audio
        if args.wav:
            write_wav(Path(args.wav), spoken.audio)
            sound_file = args.wav
    else:
        _check_phones_options(args)
        spans = read_phones(Path(args.phones), args.tier)
        audio = read_wav(Path(args.audio)) if args.audio else None
    result = model.synthesize(spans, fps=args.fps, audio=audio, emotion=args.emotion)
    result = apply_to_result(model, result, profile, directory=model_dir)
    export = ExportSettings(sound_file=sound_file, moho_fps=args.moho_fps)
    write_frames(out, result, format_name, export)
    print(f"wrote {len(result.frames)} frames at {result.fps:g} fps to {args.out} ({format_name})")
    if args.text is not None and args.wav:
        print(f"wrote the speech to {args.wav}")


def _word_timing_spans(args: argparse.Namespace, model_dir: Path) -> list[PhonemeSpan]:
    """The spans of ``--words`` (in ``--words-format``), spread by the model's duration
    model, the words read with ``--voice``."""
    from ..frontends.formats import read_timing_file
    from ..frontends.word_durations import WordDurationModel
    from ..frontends.words_to_spans import DEFAULT_VOICE, timings_to_spans

    for option, value in (("--wav", args.wav), ("--rate", args.rate)):
        if value is not None:
            raise LipstreamError(f"{option} goes with --text", where=option, code="invalid_request")
    timings = read_timing_file(Path(args.words), args.words_format)
    return timings_to_spans(timings, WordDurationModel.load(model_dir), args.voice or DEFAULT_VOICE)


def _aligned_spans(args: argparse.Namespace) -> tuple[list[PhonemeSpan], Audio]:
    """The phoneme spans of ``--audio`` by forced alignment to ``--transcript``, its
    confidence reported on stderr; the aligner's errors name the audio file."""
    from ..audio import read_wav
    from ..frontends.align import align
    from .align import read_transcript

    if not args.audio:
        raise LipstreamError(
            "--transcript needs --audio WAV, the recording it transcribes",
            where="--transcript",
            code="invalid_request",
        )
    options = (("--wav", args.wav), ("--voice", args.voice), ("--rate", args.rate))
    for option, value in (*options, ("--lang", args.lang)):
        if value is not None:
            raise LipstreamError(f"{option} goes with --text", where=option, code="invalid_request")
    audio = read_wav(Path(args.audio))
    alignment = align(audio, read_transcript(args.transcript), where=args.audio)
    print(f"alignment confidence {alignment.confidence:.2f}", file=sys.stderr)
    return alignment.phones, audio


def _check_text_options(args: argparse.Namespace) -> None:
    if args.audio:
        raise LipstreamError(
            "--audio goes with --phones; with --text the speech is espeak-ng's (--wav saves it)",
            where="--audio",
            code="invalid_request",
        )


def _check_phones_options(args: argparse.Namespace) -> None:
    options = (("--wav", args.wav), ("--voice", args.voice), ("--rate", args.rate))
    for option, value in (*options, ("--lang", args.lang)):
        if value is not None:
            raise LipstreamError(f"{option} goes with --text", where=option, code="invalid_request")


def _output_profile(args: argparse.Namespace, *, shapes: bool) -> OutputProfile | None:
    """The output profile of ``--profile`` with ``--naming``, ``--channels``, ``--visemes`` and
    ``--retarget`` laid over it, validated as the server validates ``start.output``; Rhubarb
    and Moho formats (``shapes``) default to the Preston Blair visemes."""
    from ..output.profiles import parse_profile, profile_fields

    fields = profile_fields(Path(args.profile)) if args.profile else {}
    for key in ("naming", "channels", "visemes", "retarget"):
        value = getattr(args, key)
        if value is not None:
            fields[key] = value
    if shapes and not {"visemes", "naming", "retarget"} & set(fields):
        fields["visemes"] = "preston-blair"
    return parse_profile(fields, args.profile or "command line") if fields else None


def add_synth_parser(commands: Commands) -> None:
    synth = commands.add_parser(
        "synth",
        help="frames for phones, a text, a TTS timing file or a recording and its transcript",
    )
    synth.add_argument(
        "--model",
        help="a model directory (default: the demo character's model of --engine; "
        "lipstream path demo --engine E prints where it is)",
    )
    synth.add_argument(
        "--engine",
        default="viseme-lerp",
        help="engine of the demo character's model, without --model (default viseme-lerp)",
    )
    _input_options(synth)
    synth.add_argument("--fps", type=float, default=60.0, help="output frame rate (default 60)")
    synth.add_argument(
        "--emotion", choices=EMOTIONS, help="emotion of every phoneme (default: none)"
    )
    _output_options(synth)
    synth.set_defaults(run=_synth)


def _input_options(synth: argparse.ArgumentParser) -> None:
    """What is spoken: phones, a text or TTS timings, with its speech and voice."""
    given = synth.add_mutually_exclusive_group(required=True)
    given.add_argument("--phones", help=".TextGrid, .lab or .json")
    given.add_argument(
        "--text", help="text to speak with espeak-ng (at most 1000 characters), instead of phones"
    )
    given.add_argument(
        "--words",
        metavar="FILE",
        help="word, character, viseme or phoneme timings from a TTS (JSON or JSON lines)",
    )
    given.add_argument(
        "--transcript",
        metavar="TEXT|FILE",
        help="what --audio says (the text, or a .txt file): phones by forced alignment",
    )
    synth.add_argument(
        "--words-format",
        choices=("auto", *TIMING_FORMATS),
        default="auto",
        help="format of --words (default: detected from the content)",
    )
    synth.add_argument(
        "--audio",
        help="mono WAV of the speech, for engines that use audio (with --transcript: aligned)",
    )
    synth.add_argument("--wav", help="with --text: write espeak-ng's speech to this WAV file")
    synth.add_argument(
        "--lang",
        help="with --text: espeak-ng language (de, fr-fr, cmn, ...; docs/reference/languages.md)",
    )
    synth.add_argument(
        "--voice",
        help="with --text or --words: espeak-ng voice (default en-us); with --lang, a variant"
        " (f3, m1)",
    )
    synth.add_argument(
        "--rate", type=int, help="with --text: words per minute, 80-450 (default 175)"
    )
    synth.add_argument("--tier", help="TextGrid phone tier (default: phones, MAU, phone, ...)")


def _output_options(synth: argparse.ArgumentParser) -> None:
    """The file written, its format, and the output profile the frames pass through."""
    synth.add_argument(
        "--out", required=True, help="frames file to write: .csv, .json, .tsv, .xml or .dat"
    )
    synth.add_argument(
        "--format", choices=FORMATS, help="output format (default: by the --out extension)"
    )
    synth.add_argument("--profile", help="output profile JSON file (as the server's output)")
    synth.add_argument("--naming", choices=NAMINGS, help="channel naming")
    synth.add_argument("--channels", nargs="+", metavar="NAME", help="output these channels")
    synth.add_argument("--visemes", choices=VISEME_SETS, help="output visemes, not blendshapes")
    synth.add_argument("--retarget", metavar="MAP", help="output a retarget map's rig controls")
    synth.add_argument(
        "--moho-fps", type=float, default=MOHO_FPS, help="frame rate of a Moho .dat (24-100)"
    )
