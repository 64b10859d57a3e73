"""The rig protocol's tables: the register map is consistent (no overlap, the status and limits are exactly
PLCStatus' and Limits' fields), encodes and decodes what it is given, says which fields a write touches, and
is the map docs/rig-protocols.md documents; every ADS symbol is documented. The wire itself is tested end
to end in tests/sim (the simulated PLC serving it) and tests/daq (the DAQ's clients speaking it)."""
import re
from dataclasses import fields
from pathlib import Path

import numpy as np

from protocol import ads, modbus
from protocol.plc import Limits, PLCStatus

DOC = Path(__file__).resolve().parents[2] / "docs" / "rig-protocols.md"


def _addresses():
    return [(b.address_of(n) + k, n) for b in modbus.REGISTER_MAP for n, kind in b.fields
            for k in range(2 if kind == modbus.F32 else 1)]


def test_no_two_fields_share_a_register_and_status_and_limits_are_their_dataclasses():
    regs = [a for a, _ in _addresses()]
    assert len(regs) == len(set(regs)) == sum(b.count for b in modbus.REGISTER_MAP) == 32
    assert modbus.STATUS.names == tuple(f.name for f in fields(PLCStatus))
    assert modbus.LIMITS.names == tuple(f.name for f in fields(Limits))
    assert dict(modbus.STATUS.fields)["state"] == modbus.U16 and dict(modbus.STATUS.fields)["position_mm"] == modbus.F32


def test_blocks_decode_what_they_encode():
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print("seed", seed)
    rng = np.random.default_rng(seed)
    for block in modbus.REGISTER_MAP:
        values = {n: int(rng.integers(0, 65536)) if kind == modbus.U16 else float(np.float32(rng.normal() * 100))
                  for n, kind in block.fields}
        regs = block.encode(values)
        assert len(regs) == block.count and all(0 <= r <= 0xFFFF for r in regs)
        assert block.decode(regs) == values, seed
        assert sorted(block.image(values)) == list(range(block.address, block.address + block.count))
    assert modbus.f32_to_regs(1.0) == [0x3F80, 0x0000]  # big-endian word order, high word first


def test_a_write_touches_the_fields_whose_registers_it_covers():
    sp = modbus.SETPOINTS
    assert sp.fields_written(2, 2) == ["f_end_hz"]
    assert sp.fields_written(1, 2) == ["f_start_hz", "f_end_hz"]  # half of each
    assert sp.fields_written(0, sp.count) == list(sp.names)
    assert sp.fields_written(10, 1) == [] and modbus.CONTROL.fields_written(10, 1) == ["command"]
    assert modbus.CONTROL.fields_written(11, 1) == ["heartbeat"]


def test_the_documented_register_map_is_the_code_s():
    """docs/rig-protocols.md's Modbus table, row by row: addresses, type, fields."""
    section = DOC.read_text().split("## Modbus TCP")[1].split("\n## ")[0]
    documented = {}
    for row in re.findall(r"^\|([^|]+)\|\s*(f32|u16)\s*\|[^|]+\|([^|]+)\|$", section, flags=re.M):
        cells = [int(x) for x in re.findall(r"\d+", row[0])]
        addrs = list(range(cells[0], cells[-1] + 1, cells[1] - cells[0])) if "..." in row[0] else cells
        names = re.findall(r"[a-z][a-z0-9_]*", re.sub(r"\(.*?\)", "", row[2]))
        assert len(addrs) == len(names), row
        documented |= {n: (a, row[1]) for a, n in zip(addrs, names)}
    code = {n: (b.address_of(n), kind) for b in modbus.REGISTER_MAP for n, kind in b.fields}
    assert documented == code


def test_every_ads_symbol_is_documented_once_with_its_type():
    names = [s.name for s in ads.SYMBOLS]
    assert len(names) == len(set(names)) == 18
    text = DOC.read_text()
    assert all(f"`{n}`" in text for n in names), [n for n in names if f"`{n}`" not in text]
    assert {s.field for s in ads.LIMIT_SYMBOLS} == {f.name for f in fields(Limits)}
    # and with its type: docs/rig-protocols.md lists the symbols in groups, each followed by "(REAL" or "(UINT"
    section = text.split("## ADS")[1].split("\n## ")[0]
    documented = {}
    for group in re.finditer(r"((?:`MAIN\.\w+`[,\s]*)+)\((REAL|UINT)\b", section):
        documented |= dict.fromkeys(re.findall(r"`(MAIN\.\w+)`", group[1]), group[2])
    assert documented == {s.name: s.type for s in ads.SYMBOLS}
