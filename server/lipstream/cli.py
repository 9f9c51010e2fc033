"""The ``lipstream`` command line.

Subcommands: build-demo, train, synth, serve, inspect, bench, loadtest, bridge, capture,
align, path, retarget. Every option has a help line (``lipstream <command> --help``); ``--version``
prints the version. A user-facing failure prints one line (``error [code]: where: message``) and
exits 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from lipstream_client.channels import RETARGET_PRESETS
from lipstream_client.messages import NAMINGS, VISEME_SETS

from ._version import __version__
from .bridge_command import add_bridge_parser
from .capture.command import add_capture_parser
from .config import ServerSettings, Settings, demo_model_path, load_settings
from .errors import LipstreamError
from .exports import FORMATS, MOHO_FPS
from .frontends.command import add_align_parser
from .frontends.timings import TIMING_FORMATS
from .loadtest.command import add_loadtest_parser

if TYPE_CHECKING:
    from lipstream_client import OutputProfile

    from .audio import Audio
    from .engines.base import Model
    from .models import ModelRegistry
    from .output.retarget import RetargetMap
    from .status import Report
    from .timeline import PhonemeSpan


def _build_demo(args: argparse.Namespace, settings: Settings) -> None:
    from .status import Heartbeat, to_stderr
    from .training import build_demo

    out = Path(args.out) if args.out else settings.demo_dir
    heartbeat = Heartbeat(to_stderr).start()
    try:
        written = build_demo(out, report=heartbeat.report)
    finally:
        heartbeat.stop()
    print(f"demo corpus in {out / 'corpus'}; models: {', '.join(map(str, written.values()))}")


def _train(args: argparse.Namespace, settings: Settings) -> None:
    from .corpus import CorpusWarning, load_corpus
    from .status import Heartbeat, phase, to_stderr
    from .training import resolve_engines, train_engine, train_engines

    engines = resolve_engines(args.engine)
    with warnings.catch_warnings(record=True) as ignored:
        warnings.simplefilter("always", CorpusWarning)
        corpus = load_corpus(args.corpus, progress=True, tier=args.tier)
    for warning in ignored:
        print(f"warning: {warning.message}", file=sys.stderr)
    out = Path(args.out)
    heartbeat = Heartbeat(to_stderr).start()  # a stage with no bar of its own still shows
    try:
        if args.engine == "all":
            written = train_engines(corpus, engines, out, report=heartbeat.report)
            print("trained " + ", ".join(f"{name} -> {path}" for name, path in written.items()))
            return
        with phase(f"training {args.engine} on the corpus", heartbeat.report):
            model = train_engine(corpus, engines[0], out, progress=True)
    finally:
        heartbeat.stop()
    print(f"trained {args.engine} -> {out} in {model.manifest.metrics['train_seconds']} s")


def _synth(args: argparse.Namespace, settings: Settings) -> None:
    from .audio import read_wav, write_wav
    from .engines import load_model
    from .exports import SHAPE_FORMATS, format_for
    from .exports.writer import ExportSettings
    from .phones_io import read_phones, write_frames
    from .server.profiles import apply_to_result

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
    elif args.text is not None:
        from .speech.text_frontend import speak_text

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
    from .frontends.formats import read_timing_file
    from .frontends.word_durations import WordDurationModel
    from .frontends.words_to_spans import DEFAULT_VOICE, timings_to_spans

    for option, value in (("--wav", args.wav), ("--rate", args.rate)):
        if value is not None:
            raise LipstreamError(f"{option} goes with --text", where=option, code="invalid_request")
    timings = read_timing_file(Path(args.words), args.words_format)
    return timings_to_spans(timings, WordDurationModel.load(model_dir), args.voice or DEFAULT_VOICE)


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
    from .server.profiles import parse_profile, profile_fields

    fields = profile_fields(Path(args.profile)) if args.profile else {}
    for key in ("naming", "channels", "visemes", "retarget"):
        value = getattr(args, key)
        if value is not None:
            fields[key] = value
    if shapes and not {"visemes", "naming", "retarget"} & set(fields):
        fields["visemes"] = "preston-blair"
    return parse_profile(fields, args.profile or "command line") if fields else None


IMPORTING_THE_SERVER = "importing the server (numpy, scipy, numba, FastAPI, the engines)"


def _serve(args: argparse.Namespace, settings: Settings) -> None:
    """Serve; with one worker the server listens first and starts up behind it (building the
    demo character when there are no models), so ``/healthz`` answers throughout and
    ``/readyz`` names the phase."""
    from .status import to_stderr

    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    server = settings.server.with_changes(
        workers=args.workers or settings.server.workers,
        log_level=args.log_level or settings.server.log_level,
        strict_models=args.strict_models or settings.server.strict_models,
    )
    models = Path(args.models) if args.models else settings.models
    build = args.models is None and not models.exists()
    check = args.models is None and models == settings.demo_models_dir
    if build:
        models = settings.demo_models_dir
    if args.ray or server.workers > 1:
        _serve_in_front(args, settings, models, server, build=build, check=check)
        return
    from .server.front_door import FrontDoor, bind
    from .server.open_files import raise_open_file_limit
    from .status import Heartbeat, phase

    raise_open_file_limit()  # before the first connection is accepted, as serve() would
    door = FrontDoor(bind(host, port)).start()
    heartbeat = Heartbeat(_reporting_to(to_stderr, door.note)).start()
    heartbeat.report(
        f"lipstream serve: listening on http://{host}:{port} and starting up "
        "(GET /healthz answers now; GET /readyz names the phase until it is ready)"
    )
    try:
        with phase(IMPORTING_THE_SERVER, heartbeat.report):
            from .server.runner import serve
    finally:
        heartbeat.stop()

    def prepare(report: Report) -> ModelRegistry | None:
        return _demo_ready(settings, report, build=build, check=check)

    serve(
        models.resolve(),
        host,
        port,
        server,
        prepare=prepare if build or check else None,
        sock=door.hand_over(),
    )


def _reporting_to(*reports: Report) -> Report:
    def report(line: str) -> None:
        for each in reports:
            each(line)

    return report


def _demo_ready(
    settings: Settings, report: Report, *, build: bool, check: bool
) -> ModelRegistry | None:
    """Build the demo character when there are no models, or when its cached models cannot
    serve every engine (``_cached_demo``); the cached models when the check loaded them
    (so the server does not load them twice)."""
    from .status import phase
    from .training import build_demo

    models = settings.demo_models_dir
    if build:
        report(f"no models in {models}: building the demo character first")
    elif check:
        with phase(f"checking the demo character in {models}", report):
            cached = _cached_demo(models)
        if cached is not None:
            return cached
        report(
            f"the demo character in {models} lacks an engine or was built by an older "
            "lipstream: building it again"
        )
    else:
        return None
    build_demo(settings.demo_dir, report=report)
    return None


def _serve_in_front(
    args: argparse.Namespace,
    settings: Settings,
    models: Path,
    server: ServerSettings,
    *,
    build: bool,
    check: bool,
) -> None:
    """Several workers or Ray: build and load before serving, so each worker (or replica)
    loads a model set known to load; a set that cannot be served stops here with one line."""
    from .status import Heartbeat, phase, to_stderr

    heartbeat = Heartbeat(to_stderr).start()
    try:
        with phase(IMPORTING_THE_SERVER, heartbeat.report):
            from .models import ModelRegistry
            from .server.metrics import multiprocess_directory
            from .server.runner import serve
        registry = _demo_ready(settings, heartbeat.report, build=build, check=check)
        if registry is None:
            with phase(f"loading the models in {models.resolve()}", heartbeat.report):
                registry = ModelRegistry.load(models.resolve(), strict=server.strict_models)
    finally:
        heartbeat.stop()
    if args.ray:
        _serve_on_ray(args, settings, models.resolve(), server)
        return
    registry = None
    with multiprocess_directory(server.workers):
        serve(
            models.resolve(),
            args.host or settings.host,
            settings.port if args.port is None else args.port,
            server,
            registry,
        )


def _serve_on_ray(
    args: argparse.Namespace, settings: Settings, models: Path, server: ServerSettings
) -> None:
    try:
        from .deploy.ray import serve_on_ray
    except ImportError as error:
        raise LipstreamError(
            f'--ray needs Ray Serve: pip install "lipstream[ray]" ({error})',
            where="--ray",
            code="missing_dependency",
        ) from None
    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    serve_on_ray(models, host, port, server, args.replicas)


def _stale_demo(models: Path) -> bool:
    """Whether the cached demo character cannot serve every registered engine (a model
    that no longer loads, or an engine added since it was built) or word timings (a model
    without its duration model, built before they were)."""
    return _cached_demo(models) is None


def _cached_demo(models: Path) -> ModelRegistry | None:
    """The cached demo character, loaded, when it serves every registered engine."""
    from .engines import engine_names
    from .frontends.word_durations import has_word_durations
    from .models import ModelRegistry, model_dirs

    try:
        registry = ModelRegistry.load(models)
        directories = model_dirs(models)
    except LipstreamError:
        return None
    served = {model.manifest.engine for model in registry.models.values()}
    if registry.failures or not set(engine_names()) <= served:
        return None
    if not all(has_word_durations(directory) for directory in directories):
        return None
    return registry


def _inspect(args: argparse.Namespace, settings: Settings) -> None:
    from .models import model_dirs
    from .store import read_manifest

    for directory in model_dirs(Path(args.dir)):
        manifest = read_manifest(directory)
        print(
            f"{directory}: engine {manifest.engine}, character {manifest.name}, "
            f"{len(manifest.channels)} channels at {manifest.fps:g} fps"
        )
        print(f"  hyperparameters: {json.dumps(manifest.hyperparameters, sort_keys=True)}")
        print(f"  corpus digest: {manifest.corpus_digest}")
        print(f"  metrics: {json.dumps(manifest.metrics, sort_keys=True)}")
        print(f"  channels: {', '.join(manifest.channels)}")


def _retarget(args: argparse.Namespace, settings: Settings) -> None:
    from .engines import load_model
    from .output.retarget import RETARGET_DIR, fit_map, read_pairs, save_map, write_pairs
    from .output.rig_presets import preset_pairs

    if args.model is None:
        if args.action != "show":
            raise LipstreamError(f"retarget {args.action} needs --model DIR", where="--model")
        _show_presets(args.name)
        return
    directory = Path(args.model)
    model = load_model(directory)
    if args.action == "show":
        for name, retarget in _shown_maps(model, directory, args.name).items():
            errors = retarget.reproduction_error()
            print(
                f"{name}: {len(retarget.channels)} channels -> {len(retarget.controls)} controls, "
                f"{len(errors)} key poses, largest key-pose error {max(errors.values()):.3g}"
            )
            print(f"  controls: {', '.join(retarget.controls)}")
            print(f"  keys: {', '.join(retarget.pairs.key_names)}")
        return
    if args.action == "fit":
        pairs = read_pairs(Path(args.pairs), model.channels)
        name = args.name
    else:
        pairs = preset_pairs(model, args.target)
        name = args.name or args.target
        if args.pairs_out:
            write_pairs(Path(args.pairs_out), pairs)
    retarget = fit_map(name, pairs)
    out = save_map(Path(args.out) if args.out else directory / RETARGET_DIR / name, retarget)
    worst = max(retarget.reproduction_error().values())
    print(f"wrote retarget map {name} to {out} (largest key-pose error {worst:.3g})")


def _show_presets(name: str | None) -> None:
    """The shipped rig presets (or only ``name``): the rig each drives and its controls."""
    from .output.rig_presets import PRESETS, preset

    shown = PRESETS.values() if name is None else [preset(name, "name")]
    for shipped in shown:
        arkit = ", for models with ARKit channel names" if shipped.needs_arkit else ""
        print(f"{shipped.name}: {shipped.rig}; {len(shipped.controls)} controls{arkit}")
        print(f"  controls: {', '.join(shipped.controls)}")


def _shown_maps(model: Model, directory: Path, name: str | None) -> dict[str, RetargetMap]:
    """Every map the model is served through, or only the one named (``unknown_retarget``
    when it has none of that name)."""
    from .output.rig_presets import model_maps, offered_presets

    maps = model_maps(model, directory, only=name)
    if name is None:
        return maps
    if name not in maps:
        known = ", ".join(dict.fromkeys([*offered_presets(model.channels), *maps]))
        raise LipstreamError(
            f"the model has no retarget map {name!r}; its maps: {known}",
            where=str(directory),
            code="unknown_retarget",
        )
    return {name: maps[name]}


def _bench(args: argparse.Namespace, settings: Settings) -> None:
    if (args.models or args.engines) and not args.real:
        raise LipstreamError(
            "--models and --engines go with --real", where="--models", code="invalid_request"
        )
    if args.real and (args.word_timings or args.no_engine_benches):
        raise LipstreamError(
            "--real measures the demo models on real lips; it takes no --word-timings or "
            "--no-engine-benches",
            where="--real",
            code="invalid_request",
        )
    if args.word_timings:
        _bench_word_timings(args, settings)
        return
    if args.real:
        _bench_real(args, settings)
        return
    from .bench.harness import format_engine_benches, format_table, run_bench
    from .bench.rungs import format_rungs
    from .corpus import load_corpus
    from .results_file import write_results
    from .training import DEMO_CORPUS_DIR, build_demo

    corpus_dir = Path(args.corpus) if args.corpus else settings.demo_dir / DEMO_CORPUS_DIR
    if args.corpus is None and not corpus_dir.exists():
        build_demo(settings.demo_dir, progress=True)
    path = settings.results_file(args.results, "results.json")
    results = run_bench(
        load_corpus(corpus_dir, progress=True), engine_benches=not args.no_engine_benches
    )
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print(format_table(results))
        print()
        print(format_rungs(results["rungs"]))
        print(format_engine_benches(results))


REAL_FACES_CORPUS = Path(__file__).resolve().parents[2] / "tests" / "data" / "grid" / "corpus"
"""The GRID real-face set a checkout ships (``tests/data/grid``)."""


def _bench_real(args: argparse.Namespace, settings: Settings) -> None:
    """``lipstream bench --real``: ``lipstream.bench.real_faces``."""
    from .bench.real_faces import demo_models, format_real_table, run_real_bench
    from .corpus import load_corpus
    from .results_file import write_results
    from .training import build_demo

    corpus_dir = Path(args.corpus) if args.corpus else REAL_FACES_CORPUS
    if not corpus_dir.is_dir():
        raise LipstreamError(
            "no real-face corpus here: give one made by `lipstream capture` with --corpus",
            where=str(corpus_dir),
            code="invalid_request",
        )
    models_dir = Path(args.models) if args.models else settings.demo_models_dir
    if args.models is None and not models_dir.exists():
        build_demo(settings.demo_dir, progress=True)
    path = settings.results_file(args.results, "real_faces.json")
    engines = args.engines.split(",") if args.engines else None
    results = run_real_bench(
        load_corpus(corpus_dir), demo_models(models_dir, engines), args.command_line
    )
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    print(json.dumps(results, indent=2) if args.json else format_real_table(results))


def _bench_word_timings(args: argparse.Namespace, settings: Settings) -> None:
    """``lipstream bench --word-timings``: ``lipstream.bench.word_timings``."""
    from .bench.word_timings import print_summary, run
    from .results_file import write_results

    if args.corpus is not None or args.no_engine_benches:
        raise LipstreamError(
            "--word-timings measures on espeak-ng's own speech of the demo sentences; it takes "
            "no --corpus or --no-engine-benches",
            where="--word-timings",
            code="invalid_request",
        )
    path = settings.results_file(args.results, "word_timings.json")
    results = run(["lipstream", *sys.argv[1:]])
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print_summary(results)


def _path(args: argparse.Namespace, settings: Settings) -> None:
    from .config import demo_model_path

    print(demo_model_path(args.engine, settings) if args.engine else settings.demo_models_dir)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lipstream", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"lipstream {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    demo = commands.add_parser("build-demo", help="generate the demo corpus and train every engine")
    demo.add_argument("--out", help="output directory (default: $LIPSTREAM_HOME/demo)")
    demo.set_defaults(run=_build_demo)

    train = commands.add_parser("train", help="train engines on a corpus directory")
    train.add_argument(
        "--corpus", required=True, help="corpus directory (docs/reference/corpus-formats.md)"
    )
    train.add_argument("--engine", required=True, help="an engine name, or all")
    train.add_argument(
        "--out",
        required=True,
        help="model directory to write; with --engine all, one subdirectory per engine",
    )
    train.add_argument(
        "--tier", help="TextGrid phone tier (default: corpus.json's tier, else phones/MAU/...)"
    )
    train.set_defaults(run=_train)

    synth = commands.add_parser(
        "synth", help="synthesize frames for a phones file, a text or a TTS timing file"
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
    synth.add_argument(
        "--words-format",
        choices=("auto", *TIMING_FORMATS),
        default="auto",
        help="format of --words (default: detected from the content)",
    )
    synth.add_argument("--audio", help="mono WAV of the speech, for engines that use audio")
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
    synth.add_argument("--fps", type=float, default=60.0, help="output frame rate (default 60)")
    synth.add_argument(
        "--emotion",
        choices=["neutral", "happy", "angry", "sad"],
        help="emotion of every phoneme (default: none)",
    )
    synth.add_argument(
        "--out", required=True, help="frames file to write: .csv, .json, .tsv, .xml or .dat"
    )
    synth.add_argument(
        "--format", choices=FORMATS, help="output format (default: by the --out extension)"
    )
    synth.add_argument("--tier", help="TextGrid phone tier (default: phones, MAU, phone, ...)")
    synth.add_argument("--profile", help="output profile JSON file (as the server's output)")
    synth.add_argument("--naming", choices=NAMINGS, help="channel naming")
    synth.add_argument("--channels", nargs="+", metavar="NAME", help="output these channels")
    synth.add_argument("--visemes", choices=VISEME_SETS, help="output visemes, not blendshapes")
    synth.add_argument("--retarget", metavar="MAP", help="output a retarget map's rig controls")
    synth.add_argument(
        "--moho-fps", type=float, default=MOHO_FPS, help="frame rate of a Moho .dat (24-100)"
    )
    synth.set_defaults(run=_synth)

    serve = commands.add_parser("serve", help="run the server")
    serve.add_argument(
        "--models",
        help="a model directory or a directory of them (default: $LIPSTREAM_MODELS, "
        "else the demo character, built on first use)",
    )
    serve.add_argument(
        "--host", help="interface to listen on (default: $LIPSTREAM_HOST or 127.0.0.1)"
    )
    serve.add_argument(
        "--port", type=int, help="TCP port to listen on (default: $LIPSTREAM_PORT or 8000)"
    )
    serve.add_argument(
        "--workers",
        type=_positive_int,
        help="worker processes sharing the memory-mapped models (default: $LIPSTREAM_WORKERS or 1)",
    )
    serve.add_argument(
        "--ray",
        action="store_true",
        help='serve on a local Ray Serve instance (pip install "lipstream[ray]")',
    )
    serve.add_argument(
        "--replicas",
        type=_positive_int,
        default=1,
        help="Ray Serve replicas with --ray, each loading the models once (default: 1)",
    )
    serve.add_argument(
        "--log-level",
        choices=["critical", "error", "warning", "info", "debug", "trace"],
        help="uvicorn log level (default: $LIPSTREAM_LOG_LEVEL or info)",
    )
    serve.add_argument(
        "--strict-models",
        action="store_true",
        help="exit when any model fails to load (default: $LIPSTREAM_STRICT_MODELS or serve "
        "the others and report it)",
    )
    serve.set_defaults(run=_serve)

    inspect = commands.add_parser("inspect", help="summarize a model directory")
    inspect.add_argument("dir", help="a model directory or a directory of them")
    inspect.set_defaults(run=_inspect)

    _add_retarget_parser(commands)

    bench = commands.add_parser("bench", help="benchmark every engine on held-out utterances")
    bench.add_argument("--corpus", help="corpus directory (default: the demo corpus)")
    bench.add_argument("--json", action="store_true", help="print JSON instead of a table")
    bench.add_argument(
        "--results",
        help="JSON file to write the results to (default $LIPSTREAM_HOME/bench/results.json)",
    )
    bench.add_argument(
        "--word-timings",
        action="store_true",
        help="instead: phoneme onset error of each TTS timing format against espeak-ng's own, "
        "and the real-time factor of words to spans (default file word_timings.json)",
    )
    bench.add_argument(
        "--real",
        action="store_true",
        help="instead: the demo character's models against real lips (--corpus: a capture "
        "corpus, default the checkout's GRID set; results by default in "
        "$LIPSTREAM_HOME/bench/real_faces.json)",
    )
    bench.add_argument(
        "--models",
        help="with --real: directory of the models to measure (default: the demo models)",
    )
    bench.add_argument(
        "--engines",
        help="with --real: comma-separated engines to measure (default: every model found)",
    )
    bench.add_argument(
        "--no-engine-benches",
        action="store_true",
        help="skip the engines' own benchmarks (e.g. anime-graph vs PQ-Matching)",
    )
    bench.set_defaults(run=_bench)

    add_loadtest_parser(commands)
    add_bridge_parser(commands)
    add_capture_parser(commands)
    add_align_parser(commands)

    path = commands.add_parser(
        "path", help="print where the demo character's models are (or will be built)"
    )
    path.add_argument("what", choices=["demo"], help="demo: the demo character's model directory")
    path.add_argument(
        "--engine", help="print this engine's model directory (e.g. viseme-lerp) instead"
    )
    path.set_defaults(run=_path)
    return parser


def _add_retarget_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    retarget = commands.add_parser("retarget", help="fit, build or show rig presets and maps")
    actions = retarget.add_subparsers(dest="action", required=True)
    fit = actions.add_parser("fit", help="fit a map from a key-pose pairs file")
    fit.add_argument(
        "--pairs", required=True, help="key-pose pairs, JSON or .csv (docs/how-to/retarget.md)"
    )
    fit.add_argument("--name", required=True, help="the map's name (output.retarget)")
    build = actions.add_parser("build", help="store a rig preset fitted on the model")
    build.add_argument(
        "--target", required=True, help=f"a rig preset: {', '.join(RETARGET_PRESETS)}"
    )
    build.add_argument("--name", help="the map's name (default: the preset's)")
    build.add_argument(
        "--pairs-out", help="also write its key-pose pairs to this file (.csv for CSV, else JSON)"
    )
    show = actions.add_parser(
        "show", help="list the rig presets, or with --model the maps the model is served through"
    )
    show.add_argument("name", nargs="?", help="only this preset or map")
    show.add_argument("--model", help="the model directory")
    for action in (fit, build):
        action.add_argument("--model", required=True, help="the model directory")
    for action in (fit, build):
        action.add_argument("--out", help="map directory (default: MODEL/retarget/NAME)")
    retarget.set_defaults(run=_retarget)


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.command_line = ["lipstream", *(sys.argv[1:] if argv is None else argv)]
    run: Callable[[argparse.Namespace, Settings], None] = args.run
    try:
        run(args, load_settings())
    except LipstreamError as error:
        print(
            f"error [{error.code}]: {error.where + ': ' if error.where else ''}{error.message}",
            file=sys.stderr,
        )
        return 2
    except OSError as error:
        print(f"error [io_error]: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
