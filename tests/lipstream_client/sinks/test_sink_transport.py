"""Targets parsed or refused with a code; UDP sends to a receiver that is gone counted,
never raised; a taken local port and an unknown host refused with a code."""

from __future__ import annotations

import socket

import pytest

from lipstream_client.sinks import BridgeError, Target, UdpSender, parse_local_address, parse_target


@pytest.mark.parametrize(
    ("text", "target"),
    [
        ("livelink://127.0.0.1:11112", Target("livelink", "127.0.0.1", 11112)),
        ("livelink://studio-pc", Target("livelink", "studio-pc", 11111)),
        ("vmc://localhost", Target("vmc", "localhost", 39539)),
        ("VMC://[::1]:40000", Target("vmc", "::1", 40000)),
        ("stdout", Target("stdout")),
    ],
)
def test_targets(text: str, target: Target) -> None:
    assert parse_target(text) == target


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("127.0.0.1:11111", "is not one of"),
        ("osc://127.0.0.1:9000", "unknown target kind 'osc'"),
        ("livelink://:11111", "names no host"),
        ("vmc://127.0.0.1:70000", "out of range"),
        ("vmc://127.0.0.1:port", "127.0.0.1:port"),
        ("livelink://127.0.0.1:0", "port 0"),
        ("vmc://127.0.0.1:39539/path", "only HOST:PORT"),
    ],
)
def test_malformed_targets_are_invalid_target(text: str, says: str) -> None:
    with pytest.raises(BridgeError) as caught:
        parse_target(text)
    assert caught.value.code == "invalid_target" and caught.value.where == "--to"
    assert says in caught.value.message


def test_local_addresses() -> None:
    assert parse_local_address("127.0.0.1:0") == ("127.0.0.1", 0)
    assert parse_local_address("[::1]:5000") == ("::1", 5000)
    with pytest.raises(BridgeError) as caught:
        parse_local_address("127.0.0.1")
    assert caught.value.code == "invalid_target" and caught.value.where == "--bind"


def closed_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


def test_a_receiver_that_is_gone_is_counted_not_raised() -> None:
    sender = UdpSender("127.0.0.1", closed_port())
    results = [sender.send(b"frame") for _ in range(10)]
    sender.close()
    assert sender.refused >= 1 and results.count(False) == sender.refused
    assert sender.sent + sender.refused + sender.failed == 10


def test_a_local_port_in_use_is_port_in_use() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(BridgeError) as caught:
            UdpSender("127.0.0.1", 11111, bind=("127.0.0.1", port))
    assert caught.value.code == "port_in_use" and caught.value.where == "--bind"
    assert str(port) in caught.value.message


def test_sending_from_a_chosen_local_port() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(10)
        local = closed_port()
        sender = UdpSender("127.0.0.1", receiver.getsockname()[1], bind=("127.0.0.1", local))
        sender.send(b"hello")
        data, source = receiver.recvfrom(64)
        sender.close()
    assert data == b"hello" and source == ("127.0.0.1", local)


def test_a_host_that_does_not_resolve_is_target_unreachable() -> None:
    with pytest.raises(BridgeError) as caught:
        UdpSender("no-such-host.invalid", 11111)
    assert caught.value.code == "target_unreachable" and caught.value.where == "--to"
