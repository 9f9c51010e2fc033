"""The /v1/recordings routes end to end: a real server on loopback, the shipped GRID clip as
the visitor's recordings, a training job in its own process, the new character served by
this server and by a second one over the same directories, without a restart."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.recording.recipe import ENGINES
from tests.helpers import eventually
from tests.lipstream.capture.clips import CLIP, DATA, read_clip, write_clip
from tests.lipstream.server.harness import Served, serving

GRID_SENTENCE = (DATA / "swwp2s.txt").read_text().strip()
MIN_TAKES = 2
MAX_TAKES = 4
MAX_TAKE_BYTES = 1 << 20
JOB_POLLS = 1200
JOB_PAUSE_S = 0.5
VIDEO = {"Content-Type": "video/mp4"}


@dataclass(frozen=True)
class Recording:
    served: Served
    session: str

    def url(self, tail: str = "") -> str:
        return f"{self.served.http}/v1/recordings/{self.session}{tail}"

    def upload(self, index: int, body: bytes, **headers: str) -> httpx.Response:
        return httpx.put(self.url(f"/takes/{index}"), content=body, headers={**VIDEO, **headers})

    def status(self) -> dict[str, Any]:
        answer = httpx.get(self.url())
        assert answer.status_code == 200, answer.text
        document: dict[str, Any] = answer.json()
        return document

    def finished_job(self) -> dict[str, Any]:
        def finished() -> dict[str, Any]:
            job: dict[str, Any] | None = self.status()["job"]
            return job if job is not None and job["state"] in ("done", "failed") else {}

        return eventually(finished, "the training job ends", JOB_POLLS, JOB_PAUSE_S)


def settings(recordings: Path, **changes: Any) -> ServerSettings:
    return ServerSettings(
        recordings_dir=recordings,
        recording_min_takes=MIN_TAKES,
        max_takes=MAX_TAKES,
        max_take_bytes=MAX_TAKE_BYTES,
        **changes,
    )


@pytest.fixture(scope="module")
def recordings_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("recordings")


@pytest.fixture(scope="module")
def served(words_models: Path, recordings_dir: Path) -> Iterator[Served]:
    with serving(words_models, settings(recordings_dir)) as running:
        yield running


@pytest.fixture(scope="module")
def faceless_clip(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The GRID clip's sound under black pictures: speech, but no face."""
    clip = read_clip()
    black = [np.zeros_like(picture) for picture in clip.pictures]
    path = write_clip(
        tmp_path_factory.mktemp("faceless") / "black.mp4", black, clip.sound, clip.rate
    )
    return path.read_bytes()


def open_session(served: Served, body: dict[str, Any], **headers: str) -> httpx.Response:
    # The first session without sentences has espeak-ng speak the whole script: seconds.
    return httpx.post(f"{served.http}/v1/recordings", json=body, headers=headers, timeout=120)


def recording(served: Served, name: str, sentences: list[str]) -> Recording:
    answer = open_session(served, {"name": name, "sentences": sentences})
    assert answer.status_code == 201, answer.text
    document = answer.json()
    assert [item["text"] for item in document["sentences"]] == sentences
    assert [item["index"] for item in document["sentences"]] == list(range(len(sentences)))
    assert document["limits"]["max_bytes"] == MAX_TAKE_BYTES
    return Recording(served, document["session"])


def error_of(answer: httpx.Response) -> str:
    code: str = answer.json()["error"]["code"]
    return code


def characters(served: Served) -> dict[str, list[str]]:
    listed = httpx.get(f"{served.http}/v1/characters").json()["characters"]
    return {item["name"]: item["engines"] for item in listed}


def test_recordings_become_a_served_character_and_a_bad_take_loses_nothing(
    served: Served, faceless_clip: bytes, words_models: Path, recordings_dir: Path
) -> None:
    take = recording(served, "grid-me", [GRID_SENTENCE] * 3)
    good = CLIP.read_bytes()
    for index, body in enumerate([good, faceless_clip, good]):
        answer = take.upload(index, body)
        assert answer.status_code == 200, answer.text
        assert answer.json() == {"take": index, "bytes": len(body)}
    uploaded = take.status()
    assert [(item["index"], item["status"]) for item in uploaded["takes"]] == [
        (0, "uploaded"),
        (1, "uploaded"),
        (2, "uploaded"),
    ]
    assert uploaded["job"] is None
    assert "grid-me" not in characters(served)

    started = httpx.post(take.url("/train"))
    assert started.status_code == 202, started.text
    # The job is a process of its own (capture and training take seconds): meanwhile the
    # session refuses changes, and the server serves.
    again = httpx.post(take.url("/train"))
    replaced = take.upload(0, good)
    assert (again.status_code, error_of(again)) == (409, "job_running")
    assert (replaced.status_code, error_of(replaced)) == (409, "job_running")
    demo = {"engine": "viseme-lerp", "character": "demo", "fps": 30, "text": "hi"}
    assert httpx.post(f"{served.http}/v1/synthesize", json=demo, timeout=60).status_code == 200
    job = take.finished_job()
    assert job["state"] == "done", job
    assert job["job"] == started.json()["job"] and job["character"] == "grid-me"
    assert job["progress"] == 1.0 and job["error"] is None
    takes = {item["index"]: item for item in take.status()["takes"]}
    assert takes[0]["status"] == takes[2]["status"] == "captured"
    assert takes[1]["status"] == "failed"
    assert takes[1]["error"]["code"] == "no_face" and takes[1]["error"]["where"] == "takes[1]"

    assert characters(served)["grid-me"] == sorted(ENGINES)
    for engine in ENGINES:
        request = {"engine": engine, "character": "grid-me", "fps": 30, "text": "hello there"}
        answer = httpx.post(f"{served.http}/v1/synthesize", json=request, timeout=60)
        assert answer.status_code == 200, answer.text
        result = answer.json()
        frames = np.asarray(result["data"], dtype=float)
        assert result["n_frames"] > 0 and frames.size == result["n_frames"] * result["n_channels"]
        assert np.isfinite(frames).all()

    # A second server over the same directories (another worker) serves it too.
    with serving(words_models, settings(recordings_dir)) as other:
        eventually(lambda: "grid-me" in characters(other), "the other server loads grid-me")
        assert Recording(other, take.session).status()["job"]["state"] == "done"
    again = open_session(served, {"name": "grid-me", "sentences": ["hello"]})
    assert answer.status_code == 200 and again.status_code == 409
    assert error_of(again) == "name_taken"


def test_too_few_good_takes_fail_the_job_naming_each_bad_take(
    served: Served, faceless_clip: bytes
) -> None:
    take = recording(served, "too-few", [GRID_SENTENCE] * 3)
    assert take.upload(0, faceless_clip).status_code == 200
    assert take.upload(1, CLIP.read_bytes()).status_code == 200
    assert take.upload(2, b"not a video at all").status_code == 200
    assert httpx.post(take.url("/train")).status_code == 202
    job = take.finished_job()
    assert job["state"] == "failed" and job["character"] is None
    assert job["error"]["code"] == "too_few_takes"
    failed = [(item["take"], item["code"]) for item in job["error"]["takes"]]
    assert failed == [(0, "no_face"), (2, "corrupt_video")]
    assert "1 good recording(s), at least 2 needed" in job["error"]["message"]
    assert "take 0: no_face" in job["error"]["message"]
    statuses = [(item["index"], item["status"]) for item in take.status()["takes"]]
    assert statuses == [(0, "failed"), (1, "captured"), (2, "failed")]
    assert "too-few" not in characters(served)


def test_uploads_are_bounded_in_size_and_count(served: Served, recordings_dir: Path) -> None:
    take = recording(served, "bounded", ["one", "two"])
    oversize = take.upload(0, b"\0" * (MAX_TAKE_BYTES + 1))
    assert (oversize.status_code, error_of(oversize)) == (413, "take_too_large")

    def chunks() -> Iterator[bytes]:  # no Content-Length: the stream itself is cut off
        for _ in range(MAX_TAKE_BYTES // 65536 + 2):
            yield b"\0" * 65536

    streamed = httpx.put(take.url("/takes/1"), content=chunks(), headers=VIDEO)
    assert (streamed.status_code, error_of(streamed)) == (413, "take_too_large")
    takes_dir = recordings_dir / "sessions" / take.session / "takes"
    assert list(takes_dir.iterdir()) == []
    assert take.status()["takes"] == []

    beyond = take.upload(MAX_TAKES, b"video")
    assert (beyond.status_code, error_of(beyond)) == (422, "too_many_takes")
    unknown = take.upload(2, b"video")
    assert (unknown.status_code, error_of(unknown)) == (404, "unknown_take")
    many = open_session(served, {"name": "many", "sentences": ["word"] * (MAX_TAKES + 1)})
    assert (many.status_code, error_of(many)) == (422, "too_many_takes")

    replaced = [take.upload(0, body).json() for body in (b"first take", b"second")]
    assert replaced == [{"take": 0, "bytes": 10}, {"take": 0, "bytes": 6}]
    assert [item["bytes"] for item in take.status()["takes"]] == [6]


def test_requests_are_checked(served: Served) -> None:
    taken = open_session(served, {"name": "demo"})
    assert (taken.status_code, error_of(taken)) == (409, "name_taken")
    for name in ("Upper", "", "a" * 33, "sp ace", 7):
        refused = open_session(served, {"name": name})
        assert (refused.status_code, error_of(refused)) == (400, "invalid_name"), name
    unknown = httpx.get(f"{served.http}/v1/recordings/no-such-session-at-all")
    assert (unknown.status_code, error_of(unknown)) == (404, "unknown_recording")
    take = recording(served, "checked", ["one", "two"])
    typed = take.upload(0, b"{}", **{"Content-Type": "application/json"})
    assert (typed.status_code, error_of(typed)) == (415, "unsupported_media_type")
    early = httpx.post(take.url("/train"))
    assert (early.status_code, error_of(early)) == (422, "too_few_takes")
    assert early.json()["error"]["details"] == {"uploaded": 0, "needed": MIN_TAKES}


def test_prompts_are_chosen_when_none_are_given(served: Served) -> None:
    answer = open_session(served, {"name": "prompted"})
    assert answer.status_code == 201, answer.text
    sentences = answer.json()["sentences"]
    assert len(sentences) == MAX_TAKES  # the recipe's count, capped by the setting
    assert all(item["text"].strip() for item in sentences)


def test_tokens_are_required_when_set(words_models: Path, tmp_path: Path) -> None:
    with serving(words_models, settings(tmp_path, auth_tokens=("secret",))) as locked:
        refused = open_session(locked, {"name": "locked", "sentences": ["hi"]})
        assert (refused.status_code, error_of(refused)) == (401, "unauthorized")
        answer = open_session(
            locked, {"name": "locked", "sentences": ["hi"]}, Authorization="Bearer secret"
        )
        assert answer.status_code == 201
        session = answer.json()["session"]
        status = httpx.get(f"{locked.http}/v1/recordings/{session}")
        assert status.status_code == 401
        upload = httpx.put(f"{locked.http}/v1/recordings/{session}/takes/0", content=b"x")
        assert upload.status_code == 401


def test_the_routes_can_be_switched_off(words_models: Path, tmp_path: Path) -> None:
    with serving(words_models, settings(tmp_path, recordings_enabled=False)) as off:
        answer = open_session(off, {"name": "off", "sentences": ["hi"]})
        assert (answer.status_code, error_of(answer)) == (404, "recordings_disabled")
