"""The firmware's generated C: no drift from the DBC, and bit-exact with the Python codec.

The C side is one gcc-built harness process per test session that packs and unpacks raw signal
values line by line, so hypothesis can feed it many cases without recompiling.
"""

import shutil
import subprocess

import pytest
from cantools.database.can.c_source import camel_to_snake_case
from hypothesis import given
from hypothesis import strategies as st

from firmware_proto import codec
from firmware_proto.generate import DATABASE_NAME, GENERATED_DIR, render_c_sources

from .frames import DB, MESSAGES, strategy_for


def test_generated_c_is_what_the_dbc_generates():
    for path, text in render_c_sources(DB).items():
        assert path.read_bytes() == text.encode(), f"{path.name} is stale: run python -m firmware_proto.generate"


def _harness_source() -> str:
    functions, table = [], []
    for index, message in enumerate(MESSAGES):
        prefix = f"{DATABASE_NAME}_{camel_to_snake_case(message.name)}"
        fields = [camel_to_snake_case(signal.name) for signal in message.signals]
        assignments = "".join(f"    msg.{field} = raw[{i}];\n" for i, field in enumerate(fields))
        readbacks = "".join(f"    raw[{i}] = msg.{field};\n" for i, field in enumerate(fields))
        functions.append(
            f"static int pack_{index}(const long long *raw, uint8_t *out) {{\n"
            f"    struct {prefix}_t msg;\n    memset(&msg, 0, sizeof msg);\n{assignments}"
            f"    return {prefix}_pack(out, &msg, {message.length});\n}}\n"
            f"static int unpack_{index}(const uint8_t *in, long long *raw) {{\n"
            f"    struct {prefix}_t msg;\n    int rc = {prefix}_unpack(&msg, in, {message.length});\n{readbacks}"
            f"    return rc;\n}}\n"
        )
        table.append(f"    {{{message.length}, {len(fields)}, pack_{index}, unpack_{index}}},\n")
    return (
        "#include <stdio.h>\n#include <stdlib.h>\n#include <string.h>\n"
        f'#include "{DATABASE_NAME}.h"\n\n'
        + "".join(functions)
        + "struct codec { int length; int signals; int (*pack)(const long long *, uint8_t *);"
        " int (*unpack)(const uint8_t *, long long *); };\n"
        "static const struct codec codecs[] = {\n" + "".join(table) + "};\n"
        r"""
/* "P <message> <raw>..." prints the packed payload in hex; "U <message> <hex>" prints the raw values. */
int main(void) {
    char line[4096];
    while (fgets(line, sizeof line, stdin)) {
        char *cursor = line + 1;
        const struct codec *codec = &codecs[strtol(cursor, &cursor, 10)];
        uint8_t payload[64];
        long long raw[64];
        int i, rc;
        if (line[0] == 'P') {
            for (i = 0; i < codec->signals; i++) raw[i] = strtoll(cursor, &cursor, 10);
            rc = codec->pack(raw, payload);
            if (rc < 0) printf("error %d", rc);
            for (i = 0; i < rc; i++) printf("%02x", payload[i]);
        } else {
            while (*cursor == ' ') cursor++;
            for (i = 0; i < codec->length; i++) {
                char byte[3] = {cursor[2 * i], cursor[2 * i + 1], 0};
                payload[i] = (uint8_t)strtoul(byte, NULL, 16);
            }
            rc = codec->unpack(payload, raw);
            if (rc != 0) printf("error %d", rc);
            else for (i = 0; i < codec->signals; i++) printf(i ? " %lld" : "%lld", raw[i]);
        }
        printf("\n");
        fflush(stdout);
    }
    return 0;
}
"""
    )


class Harness:
    def __init__(self, executable):
        self._process = subprocess.Popen(
            [str(executable)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1
        )

    def _ask(self, line: str) -> str:
        self._process.stdin.write(line + "\n")
        return self._process.stdout.readline().strip()

    def pack(self, index: int, raw: list[int]) -> bytes:
        return bytes.fromhex(self._ask(f"P {index} " + " ".join(map(str, raw))))

    def unpack(self, index: int, payload: bytes) -> list[int]:
        return [int(value) for value in self._ask(f"U {index} {payload.hex()}").split()]

    def close(self):
        self._process.stdin.close()
        self._process.wait(timeout=10)


@pytest.fixture(scope="module")
def harness(tmp_path_factory):
    gcc = shutil.which("gcc")
    assert gcc, "gcc is needed to check the generated C"
    build = tmp_path_factory.mktemp("c_harness")
    (build / "harness.c").write_text(_harness_source())
    executable = build / "harness"
    subprocess.run(
        [gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", f"-I{GENERATED_DIR}",
         str(build / "harness.c"), str(GENERATED_DIR / f"{DATABASE_NAME}.c"), "-o", str(executable)],
        check=True, capture_output=True, text=True,
    )
    running = Harness(executable)
    yield running
    running.close()


@pytest.mark.parametrize("index", range(len(MESSAGES)), ids=[m.name for m in MESSAGES])
@given(data=st.data())
def test_generated_c_round_trips_codec_bytes(harness, index, data):
    dbc_message = MESSAGES[index]
    _can_id, payload = codec.encode(data.draw(strategy_for(dbc_message)))
    raw_values = dbc_message.decode(payload, decode_choices=False, scaling=False)
    raw = [raw_values[signal.name] for signal in dbc_message.signals]

    assert harness.pack(index, raw) == payload
    assert harness.unpack(index, payload) == raw
