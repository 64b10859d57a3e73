"""A model as an FMI 2.0 Co-Simulation FMU, built from C source by the install's C compiler.

The FMU (a zip) holds modelDescription.xml, sources/ (model.c from identify.export.ccode, the fixed
wrapper fmi2/fmi2_cs.c and the FMI 2 headers, vendored: BSD-2-Clause, Modelica Association) and
binaries/<platform>/<identifier>.so. Nothing in it needs Python. docs/export.md says why FMI 2.0
Co-Simulation.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import zipfile
from datetime import datetime, timezone
from pathlib import Path
from xml.sax.saxutils import quoteattr

from ..errors import ModelError
from ..model import SparseModel
from . import ccode

FMI2_DIR = Path(__file__).with_name("fmi2")
#: what the FMU's sources/ carries besides model.c (the wrapper first: the one file to compile)
FMI2_SOURCES = ("fmi2_cs.c", "fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: DefaultExperiment's communication step, s
DEFAULT_STEP_S = 1e-3
#: units of the base-excited rig's signals (states m/s and m, table acceleration m/s2): modelDescription units
RIG_UNITS = {"q1": "m/s", "q2": "m", "zdd": "m/s2"}
_UNIT_EXPONENTS = {"m/s": 'm="1" s="-1"', "m": 'm="1"', "m/s2": 'm="1" s="-2"'}
_DESCRIPTIONS = {"q1": "relative velocity", "q2": "relative displacement", "zdd": "table acceleration"}


class CompilerError(ModelError):
    """No C compiler, or it failed: the operator installs one or exports --format c."""


def model_identifier(stem: str) -> str:
    """A C identifier from a file name: the FMU's modelIdentifier and its binary's name."""
    ident = re.sub(r"\W", "_", stem, flags=re.ASCII) or "model"
    return ident if not ident[0].isdigit() else "m_" + ident


def platform() -> tuple[str, str]:
    """(FMI platform folder, shared-library suffix) of this machine."""
    if sys.maxsize <= 2**32:
        raise CompilerError("FMU export needs a 64-bit platform")
    if sys.platform.startswith("linux"):
        return "linux64", ".so"
    if sys.platform == "darwin":
        return "darwin64", ".dylib"
    raise CompilerError(f"FMU export builds with gcc/clang on Linux or macOS; this is {sys.platform} "
                        "(export --format c and build the FMU's sources with your compiler)")


def find_compiler() -> list[str]:
    """The C compiler command: $CC, else cc, gcc or clang on PATH; CompilerError saying so when none is."""
    if os.environ.get("CC"):
        cmd = shlex.split(os.environ["CC"])
        if shutil.which(cmd[0]):
            return cmd
        raise CompilerError(f"no C compiler: CC={os.environ['CC']!r} is not an executable on PATH (an FMU is built "
                            "from C source; set CC to a compiler, or export --format c and build it yourself)")
    for name in ("cc", "gcc", "clang"):
        if shutil.which(name):
            return [name]
    raise CompilerError("no C compiler found (looked for $CC, cc, gcc, clang on PATH): an FMU is built from C "
                        "source; install one (Debian: apt-get install gcc), or export --format c and build it "
                        "yourself")


def model_description(model: SparseModel, identifier: str, title: str) -> str:
    """modelDescription.xml (FMI 2.0, Co-Simulation); value references as fmi2/fmi2_cs.c lays them out."""
    rig = all(s in RIG_UNITS for s in model.states + model.inputs)
    ns, ni = len(model.states), len(model.inputs)
    coefs, names = ccode.coefficients(model), ccode.coefficient_names(model)

    def var(name, vr, attrs, description, real=""):
        return (f'    <ScalarVariable name={quoteattr(name)} valueReference="{vr}" {attrs} '
                f'description={quoteattr(description)}><Real{real}/></ScalarVariable>')

    def unit(signal):
        return f' unit="{RIG_UNITS[signal]}"' if rig else ""

    rows = [var(s, i, 'causality="output" variability="continuous" initial="calculated"',
                _DESCRIPTIONS.get(s, "state") if rig else "state", unit(s)) for i, s in enumerate(model.states)]
    rows += [var(s, ns + j, 'causality="input" variability="continuous"',
                 (_DESCRIPTIONS.get(s, "input") if rig else "input") + ", held over a communication step",
                 f' start="0"{unit(s)}') for j, s in enumerate(model.inputs)]
    rows += [var(n, ns + ni + k, 'causality="parameter" variability="tunable"', f"coefficient of {t} in {eq}",
                 f' start="{c!r}"') for k, (n, (eq, t, c)) in enumerate(zip(names, coefs))]
    base = ns + ni + len(coefs)
    rows += [var(f"{s}_start", base + i, 'causality="parameter" variability="fixed"', f"{s} at the start",
                 f' start="0"{unit(s)}') for i, s in enumerate(model.states)]
    rows += [var("max_step_s", base + ns, 'causality="parameter" variability="fixed"',
                 "longest internal RK4 step, s", f' start="{ccode.max_step_s(model)!r}" unit="s"')]
    units = "".join(f'    <Unit name="{u}"><BaseUnit {_UNIT_EXPONENTS[u]}/></Unit>\n'
                    for u in sorted(set(RIG_UNITS.values()))) if rig else ""
    units += '    <Unit name="s"><BaseUnit s="1"/></Unit>\n'
    outputs = "".join(f'      <Unknown index="{i + 1}" dependencies=""/>\n' for i in range(ns))
    initial = "".join(f'      <Unknown index="{i + 1}" dependencies="{base + i + 1}"/>\n' for i in range(ns))
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(identifier)} guid="{{{ccode.model_id(model)}}}"
  description={quoteattr(title)} generationTool="shakeid export" generationDateAndTime="{now}"
  variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{identifier}" canHandleVariableCommunicationStepSize="true"
    canInterpolateInputs="true" maxOutputDerivativeOrder="0" canGetAndSetFMUstate="true">
    <SourceFiles>
      <File name="{FMI2_SOURCES[0]}"/>
    </SourceFiles>
  </CoSimulation>
  <UnitDefinitions>
{units}  </UnitDefinitions>
  <DefaultExperiment startTime="0" stepSize="{DEFAULT_STEP_S!r}"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{outputs}    </Outputs>
    <InitialUnknowns>
{initial}    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def build_fmu(model: SparseModel, out: Path, title: str) -> Path:
    """Write the FMU at `out` (*.fmu; replaced only once the new one is built). CompilerError when there is no
    compiler or it fails (its output in the message)."""
    out = Path(out)
    identifier = model_identifier(out.stem)
    folder, suffix = platform()
    compiler = find_compiler()
    with tempfile.TemporaryDirectory(prefix="shakeid-fmu-") as tmp:
        root = Path(tmp)
        src = root / "sources"
        src.mkdir()
        (src / "model.c").write_text(ccode.c_source(model, title))
        for name in FMI2_SOURCES:
            shutil.copyfile(FMI2_DIR / name, src / name)
        (root / "modelDescription.xml").write_text(model_description(model, identifier, title))
        binary = root / "binaries" / folder / (identifier + suffix)
        binary.parent.mkdir(parents=True)
        cmd = compiler + ["-shared", "-fPIC", "-O2", "-fvisibility=hidden", "-std=c99", "-I", str(src),
                          "-o", str(binary), str(src / FMI2_SOURCES[0]), "-lm"]
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        except OSError as exc:
            raise CompilerError(f"the C compiler {compiler[0]} could not be run: {exc.strerror or exc}") from None
        if p.returncode != 0:
            raise CompilerError(f"the C compiler failed building the FMU ({' '.join(cmd[:1])} exit {p.returncode}):\n"
                                + (p.stderr or p.stdout).strip()[-2000:])
        part = out.with_name(out.name + ".part")
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in sorted(root.rglob("*")):
                if f.is_file():
                    zf.write(f, f.relative_to(root).as_posix())
        os.replace(part, out)
    return out
