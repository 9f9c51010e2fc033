"""The first-start bench reads steps and silences from a server's stamped output."""

from __future__ import annotations

from lipstream.bench.first_start import Step, longest_silence, steps_from

OUTPUT = [
    (0.3, "lipstream serve: listening on http://127.0.0.1:8765 and starting up"),
    (0.31, "importing the server (numpy, scipy, numba, FastAPI, the engines) ..."),
    (1.8, 'INFO:     127.0.0.1:5000 - "GET /readyz HTTP/1.1" 503 Service Unavailable'),
    (2.1, "importing the server (numpy, scipy, numba, FastAPI, the engines): done in 1.8 s"),
    (2.2, "INFO:     training dam and compiling its kernels ..."),
    (3.0, 'INFO:     127.0.0.1:5002 - "GET /healthz HTTP/1.1" 200 OK'),
    (3.7, "INFO:     training dam and compiling its kernels ...: 1 s"),
    (
        5.9,
        "INFO:     training dam and compiling its kernels: done in 3.7 s "
        "(training 2.5 s, compiling 1.2 s, CPU 3.1 s)",
    ),
    (6.0, "demo corpus:  50%|#####     | 166/332"),
]


def test_the_steps_are_the_done_lines() -> None:
    assert steps_from(OUTPUT) == [
        Step("importing the server (numpy, scipy, numba, FastAPI, the engines)", 1.8, 2.1),
        Step(
            "training dam and compiling its kernels",
            3.7,
            5.9,
            "training 2.5 s, compiling 1.2 s, CPU 3.1 s",
        ),
    ]


def test_the_longest_silence_leaves_out_the_probes_own_log_lines() -> None:
    # spoken at 0.3, 0.31, 2.1, 2.2, 3.7, 5.9, 6.0, then ready at 7.5: the gap 3.7 -> 5.9
    before_ready = longest_silence(OUTPUT, until=7.5)
    assert before_ready is not None and abs(before_ready - 2.2) < 1e-9
    later = longest_silence(OUTPUT, until=9.0)
    assert later is not None and abs(later - 3.0) < 1e-9
    assert longest_silence([], until=1.0) is None
