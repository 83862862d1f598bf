"""The OPC UA package's parsers and conversions, without a server: the device map, the
users file, and process data ↔ OPC UA variants (property-based where input is open)."""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np
import pytest
from asyncua import ua
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.opcua.arguments import ArgumentError, data_variant, input_value, option_of
from plugcell.devices.opcua.device_map import DeviceMapError, load_device_map, parse_device_map
from plugcell.devices.opcua.listen import bind_error, listen_url
from plugcell.devices.opcua.users import UserBook, UsersFileError, hash_password
from plugcell.framework.data import to_data
from plugcell.framework.messages import Command, CommandTypes, DataTypes

MAP = Path(__file__).resolve().parent / "gripper.toml"
GOOD = MAP.read_text()


def test_the_gripper_map_reads_as_its_catalogue():
    device = load_device_map(MAP)
    assert (device.name, device.vendor) == ("GRIPPER", "plugcell tests")
    kinds = [(c.command.name, c.command.type.value, c.action) for c in device.commands]
    assert kinds == [("Open", "NoData", "method"), ("Close", "SingleData", "method"),
                     ("Force", "SingleData", "read"), ("WatchForce", "MultipleData", "subscribe"),
                     ("StopWatch", "StopData", "")]
    close = device.command("Close")
    assert close.arguments == ("data",) and close.object.endswith(";s=Gripper")
    assert close.command.input_data_type is DataTypes.Double
    assert device.command("WatchForce").interval_ms == 20.0
    assert device.command("WatchForce").command.timeout == 600.0


BAD = [
    ("", "no [[command]]"),
    ("[device]\nname = 3\n[[command]]\nname='A'\ntype='StopData'\n",
     "[device]: name must be a string"),
    ("[[command]]\nname = 'A'\ntype = 'Sometimes'\n", "command 1 ('A'): type 'Sometimes'"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\n", "a NoData command needs one of"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\nread = 'ns=1;s=X'\n",
     "read does not fit a NoData command"),
    ("[[command]]\nname = 'A'\ntype = 'SingleData'\nread = 'ns=1;s=X'\n",
     "read needs output"),
    ("[[command]]\nname = 'A'\ntype = 'SingleData'\nread = 'Gripper.Force'\n"
     "output = {type='Double'}\n", "is not an OPC UA node id"),
    ("[[command]]\nname = 'A'\ntype = 'SingleData'\nread = 'ns=1;s=X'\n"
     "output = {type='Float'}\n", "type 'Float' is not one of"),
    ("[[command]]\nname = 'A'\ntype = 'SingleData'\nread = 'ns=1;s=X'\n"
     "output = {type='Double', size=[0]}\n", "size [0] is not a list of dimensions"),
    ("[[command]]\nname = 'A'\ntype = 'MultipleData'\nsubscribe = 'ns=1;s=X'\n"
     "output = {type='Double'}\n", "needs a StopData command"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\nmethod = 'ns=1;s=X'\nwrite = 'ns=1;s=Y'\n",
     "one action per command"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\nmethod = 'ns=1;s=X'\nspeed = 3\n",
     "unknown keys ['speed']"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\nmethod = 'ns=1;s=X'\narguments = ['data']\n",
     "arguments name 'data' but the command has no input"),
    ("[[command]]\nname = 'A'\ntype = 'NoData'\nmethod = 'ns=1;s=X'\ntimeout = -1\n",
     "Expected `float` > 0.0"),
    ("[[command]]\nname = 'A'\ntype = 'StopData'\n[[command]]\nname = 'A'\ntype = 'StopData'\n",
     "duplicate command names"),
    ("[gadget]\n", "unknown tables ['gadget']"),
    ("[[command]\n", "not TOML"),
]


@pytest.mark.parametrize(("text", "reason"), BAD)
def test_a_bad_map_is_refused_naming_the_file_and_the_element(text, reason):
    with pytest.raises(DeviceMapError) as err:
        parse_device_map(text, "device.toml")
    assert str(err.value).startswith("device.toml")
    assert reason in str(err.value)


def test_a_missing_map_file_names_the_file(tmp_path):
    with pytest.raises(DeviceMapError, match=r"nothing\.toml: cannot read"):
        load_device_map(tmp_path / "nothing.toml")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(GOOD)), st.integers(0, 12),
                          st.text(max_size=6)), min_size=1, max_size=4))
def test_any_damage_to_a_map_is_refused_with_a_reason_or_still_a_map(edits):
    text = GOOD
    for at, cut, insert in edits:
        text = text[:at] + insert + text[at + cut:]
    try:
        device = parse_device_map(text, "m.toml")
    except DeviceMapError as exc:
        assert str(exc).startswith("m.toml")
    else:
        assert device.commands


VALUES = st.one_of(st.integers(-3, 10**6), st.floats(allow_nan=False, allow_infinity=False),
                   st.booleans(), st.text(max_size=12),
                   st.lists(st.integers(-2, 700), max_size=4), st.sampled_from(
                       ["NoData", "SingleData", "MultipleData", "StopData", "Double", "ns=1;s=X",
                        "nsu=urn:x;s=Y", "i=85", "data", "option"]))
KEYS = ["name", "type", "method", "read", "write", "subscribe", "object", "timeout", "info",
        "arguments", "interval_ms", "success_code", "colour"]


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.dictionaries(st.sampled_from(KEYS), VALUES, max_size=6), min_size=1,
                max_size=3),
       st.sampled_from([None, "Double", "Integer", "Byte", "Bogus"]),
       st.lists(st.integers(-2, 5), max_size=3))
def test_any_structure_of_commands_is_refused_with_a_reason_or_a_consistent_map(
        commands, data_type, size):
    lines = []
    for entry in commands:
        lines.append("[[command]]")
        lines += [f"{key} = {_toml(value)}" for key, value in entry.items()]
        if data_type:
            lines.append(f"output = {{ type = {json.dumps(data_type)}, size = {_toml(size)} }}")
    try:
        device = parse_device_map("\n".join(lines) + "\n", "s.toml")
    except DeviceMapError as exc:
        assert str(exc).startswith("s.toml")
    else:
        for mapped in device.commands:
            assert (mapped.action == "") == (mapped.command.type is CommandTypes.StopData)


def test_users_file_and_passwords(tmp_path):
    path = tmp_path / "users.toml"
    path.write_text(f'[users]\nalice = "{hash_password("s3cret")}"\n')
    book = UserBook.load(path)
    assert book.check("alice", "s3cret")
    assert not book.check("alice", "s3cret ") and not book.check("bob", "s3cret")
    assert not book.check(None, None)
    for text, reason in [
        ("users = 3\n", "no [users] table"),
        ("[users]\n", "no [users] table"),
        ('[users]\n"al ice" = "x"\n', "user 'al ice'"),
        ("[users]\nalice = 5\n", "must be a password hash string"),
        ('[users]\nalice = "s3cret"\n', "not a password hash"),
        ('[users]\nalice = "scrypt$3$8$1$00$00"\n', "parameters out of range"),
        ('[users]\nalice = "scrypt$16384$8$1$zz$00"\n', "malformed password hash"),
        ("[people]\n", "unknown keys ['people']"),
        ("[users\n", "not TOML"),
    ]:
        path.write_text(text)
        with pytest.raises(UsersFileError) as err:
            UserBook.load(path)
        assert str(err.value).startswith(str(path)) and reason in str(err.value), text


SHAPES = {DataTypes.Byte: "u1", DataTypes.Integer: "<i4", DataTypes.Double: "<f8",
          DataTypes.Boolean: "?"}


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(SHAPES, key=lambda t: t.value)),
       st.lists(st.integers(1, 5), min_size=1, max_size=3), st.integers(0, 2**32 - 1))
def test_data_goes_out_as_a_variant_and_comes_back_unchanged(data_type, shape, seed):
    rng = np.random.default_rng(seed)
    values = (rng.integers(0, 2, shape).astype(bool) if data_type is DataTypes.Boolean
              else rng.integers(0, 250, shape).astype(SHAPES[data_type]))
    data = to_data(values, data_type, tuple(shape))
    variant = data_variant(data)
    command = Command(name="Echo", type=CommandTypes.SingleData, input_data_type=data_type,
                      input_data_size=tuple(shape))
    wire = ua.ua_binary.variant_from_binary(ua.utils.Buffer(ua.ua_binary.variant_to_binary(
        variant)))  # through OPC UA's binary encoding
    back = input_value(wire, command)
    assert back == data


def test_wrong_variants_are_refused_with_the_reason():
    snap = Command(name="SnapShot", type=CommandTypes.SingleData,
                   input_data_type=DataTypes.Integer, input_data_size=(1,))
    assert input_value(ua.Variant(5, ua.VariantType.Int32), snap).size == (1,)
    assert input_value(ua.Variant([5], ua.VariantType.Int32), snap).size == (1,)
    cases = [
        (ua.Variant(5.0, ua.VariantType.Double),
         "SnapShot: argument Data: Int32 expected (Integer[1]), got scalar Double"),
        (ua.Variant([1, 2], ua.VariantType.Int32),
         "SnapShot: argument Data: size [2] does not match the declared [1]"),
        (ua.Variant(), "SnapShot: argument Data: Integer[1] expected, got nothing"),
        (None, "SnapShot: argument Data: Integer[1] expected, got nothing"),
    ]
    for variant, reason in cases:
        with pytest.raises(ArgumentError) as err:
            input_value(variant, snap)
        assert str(err.value) == reason
    assert option_of(ua.Variant(), "SnapShot") == ""
    with pytest.raises(ArgumentError, match="Option must be a String, got Int32\\[2\\]"):
        option_of(ua.Variant([1, 2], ua.VariantType.Int32), "SnapShot")


def test_a_random_map_fuzz_is_seeded_and_bounded():
    rng = random.Random(7)
    refused = 0
    for _ in range(2000):
        chars = list(GOOD)
        for _ in range(rng.randint(1, 5)):
            chars[rng.randrange(len(chars))] = rng.choice("[]{}=\"'\n ;,.0x")
        try:
            parse_device_map("".join(chars), "f.toml")
        except DeviceMapError:
            refused += 1
    assert refused > 0


@settings(max_examples=100, deadline=None)
@given(st.lists(st.text(max_size=8), min_size=1, max_size=6))
def test_strings_go_out_and_come_back_unchanged(texts):
    data = to_data(texts, DataTypes.String, (-1,))
    command = Command(name="Say", type=CommandTypes.SingleData, input_data_type=DataTypes.String,
                      input_data_size=(-1,))
    wire = ua.ua_binary.variant_from_binary(ua.utils.Buffer(ua.ua_binary.variant_to_binary(
        data_variant(data))))
    assert input_value(wire, command) == data


@pytest.mark.parametrize(("host", "port", "url"), [
    ("127.0.0.1", 4840, "opc.tcp://127.0.0.1:4840/plugcell"),
    (" 0.0.0.0 ", 1, "opc.tcp://0.0.0.0:1/plugcell"),
    ("localhost", 65535, "opc.tcp://localhost:65535/plugcell"),
    ("cell-7.example.org.", 4840, "opc.tcp://cell-7.example.org.:4840/plugcell"),
    ("::1", 4840, "opc.tcp://[::1]:4840/plugcell"),
    ("[::1]", 4840, "opc.tcp://[::1]:4840/plugcell"),
])
def test_the_gateway_listens_where_host_and_port_say(host, port, url):
    assert listen_url(host, port) == url


@pytest.mark.parametrize(("host", "port", "reason"), [
    ("127.0.0.1:4850", 4840, "--host '127.0.0.1:4850' holds a port: --host takes a host name "
                             "or address; give the port with --port (--host 127.0.0.1 --port "
                             "4850)"),
    ("localhost:4850", 4840, "(--host localhost --port 4850)"),
    (":4850", 4840, "(--host 127.0.0.1 --port 4850)"),
    ("[::1]:4850", 4840, "(--host [::1] --port 4850)"),
    ("opc.tcp://127.0.0.1:4850/plugcell", 4840, "is a URL: --host takes a host name"),
    ("localhost/plugcell", 4840, "holds a path"),
    ("", 4840, "--host is empty"),
    ("two words", 4840, "is not a host name or an IP address"),
    ("-bad-", 4840, "is not a host name or an IP address"),
    ("127.0.0.1", 0, "--port 0: a TCP port is 1…65535"),
    ("127.0.0.1", 70000, "--port 70000: a TCP port is 1…65535"),
])
def test_a_host_or_port_mistake_is_named(host, port, reason):
    with pytest.raises(ValueError) as caught:
        listen_url(host, port)
    assert reason in str(caught.value) and "\n" not in str(caught.value)


@given(st.text(max_size=80), st.integers(-10, 70000))
@settings(max_examples=300, deadline=None)
def test_any_host_is_a_url_asyncua_can_read_or_one_line_why_not(host, port):
    from urllib.parse import urlparse

    try:
        url = listen_url(host, port)
    except ValueError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    parsed = urlparse(url)  # what asyncua does with the endpoint: it must not fail
    assert parsed.scheme == "opc.tcp" and parsed.port == port and parsed.path == "/plugcell"
    assert parsed.hostname and listen_url(parsed.hostname, port) == url.lower()


def test_a_bind_failure_is_one_line_naming_the_cause():
    import errno
    import socket

    busy = OSError(errno.EADDRINUSE, "address already in use")
    assert bind_error(busy, "127.0.0.1", 4840) == (
        "port 4840 on 127.0.0.1 is in use (another OPC UA server or gateway?): stop it, or "
        "choose another port with --port")
    assert "not an address of this machine" in bind_error(
        OSError(errno.EADDRNOTAVAIL, "cannot assign"), "10.9.9.9", 4840)
    assert bind_error(socket.gaierror(-2, "Name or service not known"), "nohost", 4840) == (
        "unknown host 'nohost' (Name or service not known): give a name this machine resolves")
