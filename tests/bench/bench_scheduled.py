"""What one control sample costs through each interface of the controller FMU.

    python tests/bench/bench_scheduled.py [--samples 500] [--rounds 20] [--warmup 200]
                                          [--no-native]

Three instances of FullPoseController in one process, each from the same hover state (the
plant's outputs at rest at [0, 0, -3] as its inputs, the reference there, set once and held):
FMI 3.0 Scheduled Execution, each sample one ``fmi3ActivateModelPartition(sample, t)``; the
FMI 3.0 co-simulation interface of the same archive, each sample one ``fmi3DoStep(t, Ts)``; the
FMI 2.0 FMU, each sample one ``fmi2DoStep(t, Ts)``.  The calls are timed one by one
(``time.perf_counter_ns`` around the raw ctypes call, which is in the figure), ``--rounds``
rounds of ``--samples`` calls per instance, interleaved so that drift of the machine hits all
three alike, after ``--warmup`` untimed samples each.  A fourth row times a call that does
nothing through the same path (``fmi3GetFloat64`` of no variable on the Scheduled Execution
instance: ctypes, the timer and the glue's entry check): the floor under the three.  Prints
per row the mean, median and p99 in microseconds, the ratios of Scheduled Execution to the
two others, and whether the three instances' rotor commands agree to the bit at the end (the
controller flies: one QP iteration each, not idle).

Then, where a C compiler is found (``cc``, or ``$CC``; ``--no-native`` skips it), the same
three from C: a small harness (in this file) loads the two binaries with dlopen, sets the same
inputs, and times every call with clock_gettime, without Python or ctypes around it: the
cost of the glue and the sample alone.  Asserts nothing.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3ScheduledExecution, FMU3Slave

from plant.common.artifacts import find_artifact

TS = 0.002
CLOCK = 5000  # the clock `sample` (fmu_src/common/fmi3_scheduled.h)
POS0 = [0.0, 0.0, -3.0]


def artifact(package: str, name: str) -> Path:
    return find_artifact(package, "fmus", name)


def hover_inputs(tmp: Path) -> dict[str, list[float]]:
    """The FMI 3.0 plant's outputs at rest at POS0, by variable name."""
    path = artifact("plant", "fmi3/MultirotorPlant.fmu")
    md = read_model_description(str(path))
    extract(str(path), str(tmp / "plant"))
    s = FMU3Slave(guid=md.guid, unzipDirectory=str(tmp / "plant"),
                  modelIdentifier="MultirotorPlant", instanceName="plant")
    s.instantiate()
    vr = {v.name: (v.valueReference, int(np.prod(v.shape)) if v.shape else 1)
          for v in md.modelVariables}
    s.enterInitializationMode(startTime=0.0)
    s.setFloat64([vr["pos0"][0]], POS0)
    s.exitInitializationMode()
    out = {v.name: list(s.getFloat64([vr[v.name][0]], vr[v.name][1]))
           for v in md.modelVariables if v.causality == "output" and v.type == "Float64"}
    s.terminate()
    s.freeInstance()
    return out


class Fmi3Controller:
    """The FMI 3.0 controller through one interface: `step(t)` is one sample."""

    def __init__(self, tmp: Path, scheduled: bool, inputs: dict[str, list[float]]):
        path = artifact("controller", "fmi3/FullPoseController.fmu")
        md = read_model_description(str(path))
        folder = tmp / "ctrl3"
        if not folder.exists():
            extract(str(path), str(folder))
        cls = FMU3ScheduledExecution if scheduled else FMU3Slave
        self.fmu = cls(guid=md.guid, unzipDirectory=str(folder),
                       modelIdentifier="FullPoseController",
                       instanceName="se" if scheduled else "cs3")
        self.fmu.instantiate()
        self.vr = {v.name: (v.valueReference, int(np.prod(v.shape)) if v.shape else 1)
                   for v in md.modelVariables}
        measured = {v.name for v in md.modelVariables if v.causality == "input"}
        self.fmu.enterInitializationMode(startTime=0.0)
        for name, values in inputs.items():
            if name in measured:
                self.fmu.setFloat64([self.vr[name][0]], values)
        self.fmu.setFloat64([self.vr["pos_ref"][0]], POS0)
        self.fmu.exitInitializationMode()
        dll, c = self.fmu.dll, self.fmu.component
        if scheduled:
            activate = dll.fmi3ActivateModelPartition
            self.step = lambda t: activate(c, CLOCK, t)
        else:
            do_step = dll.fmi3DoStep
            flags = [ctypes.c_bool() for _ in range(3)]
            last = ctypes.c_double()
            refs = [ctypes.byref(f) for f in flags] + [ctypes.byref(last)]
            self.step = lambda t: do_step(c, t, TS, True, *refs)

    def commands(self) -> np.ndarray:
        vr, n = self.vr["omega_cmd"]
        return np.array(self.fmu.getFloat64([vr], n))


class Fmi2Controller:
    """The FMI 2.0 controller: `step(t)` is one fmi2DoStep(t, Ts)."""

    def __init__(self, tmp: Path, inputs: dict[str, list[float]]):
        path = artifact("controller", "FullPoseController.fmu")
        md = read_model_description(str(path))
        extract(str(path), str(tmp / "ctrl2"))
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(tmp / "ctrl2"),
                             modelIdentifier="FullPoseController", instanceName="cs2")
        self.fmu.instantiate()
        self.vr = {v.name: v.valueReference for v in md.modelVariables
                   if v.causality == "input" or v.name.startswith("omega_cmd[")}
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, values in [*inputs.items(), ("pos_ref", POS0)]:
            refs = [self.vr.get(f"{name}[{i + 1}]") for i in range(len(values))]
            if len(values) == 1 and name in self.vr:
                refs = [self.vr[name]]
            if None not in refs:
                self.fmu.setReal(refs, list(values))
        self.fmu.exitInitializationMode()
        do_step, c = self.fmu.dll.fmi2DoStep, self.fmu.component
        self.step = lambda t: do_step(c, t, TS, True)

    def commands(self) -> np.ndarray:
        return np.array(self.fmu.getReal([self.vr[f"omega_cmd[{i + 1}]"] for i in range(8)]))


def timed(step, k0: int, n: int) -> np.ndarray:
    """n samples from instant k0, each call timed: nanoseconds."""
    clock = time.perf_counter_ns
    out = np.empty(n)
    for i in range(n):
        t = (k0 + i) * TS
        a = clock()
        status = step(t)
        out[i] = clock() - a
        if status != 0:
            raise RuntimeError(f"sample at t = {t}: status {status}")
    return out


# The native harness: argv SE3_SO FMI2_SO TOKEN ROUNDS SAMPLES WARMUP, the inputs on stdin as
# lines "vr n v1 ... vn" (FMI 3.0 value references; the FMI 2.0 elements are vr .. vr + n - 1).
# Prints per interface "name mean_us median_us p99_us", then "same 0|1" (rotor commands).
HARNESS = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "fmi2Functions.h"
#include "fmi3Functions.h"

#define MAXV 64
static double now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}
static void logger3(fmi3InstanceEnvironment e, fmi3Status s, fmi3String c, fmi3String m) {
    (void)e, (void)c;
    if (s > fmi3Warning) fprintf(stderr, "%s\n", m);
}
static void logger2(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c,
                 fmi2String m, ...) {
    (void)e, (void)n, (void)c;
    if (s > fmi2Warning) fprintf(stderr, "%s\n", m);
}
static int cmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}
static void report(const char *name, double *ns, int n) {
    double sum = 0;
    int i;
    for (i = 0; i < n; i++) sum += ns[i];
    qsort(ns, (size_t)n, sizeof *ns, cmp);
    printf("%s %.4f %.4f %.4f\n", name, sum / n / 1e3, ns[n / 2] / 1e3,
           ns[(int)(0.99 * (n - 1))] / 1e3);
}
#define SYM(h, T, name) T *name = (T *)dlsym(h, #name)
int main(int argc, char **argv) {
    void *h3, *h2;
    int rounds, samples, warmup, n, r, k, i, nv = 0, same;
    unsigned vrs[MAXV], ns_[MAXV];
    double vals[MAXV][64], *cost[3], w3[8], w2[8];
    fmi3Instance se, cs;
    fmi2Component c2;
    fmi3Boolean b1, b2, b3;
    fmi3Float64 last;
    fmi2CallbackFunctions cb2 = {logger2, calloc, free, NULL, NULL};
    if (argc != 7) return 2;
    h3 = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    h2 = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (!h3 || !h2) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    rounds = atoi(argv[4]), samples = atoi(argv[5]), warmup = atoi(argv[6]);
    while (nv < MAXV && scanf("%u %u", &vrs[nv], &ns_[nv]) == 2) {
        for (i = 0; i < (int)ns_[nv]; i++) if (scanf("%lf", &vals[nv][i]) != 1) return 2;
        nv++;
    }
    {
        SYM(h3, fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation);
        SYM(h3, fmi3InstantiateScheduledExecutionTYPE, fmi3InstantiateScheduledExecution);
        SYM(h3, fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode);
        SYM(h3, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode);
        SYM(h3, fmi3SetFloat64TYPE, fmi3SetFloat64);
        SYM(h3, fmi3GetFloat64TYPE, fmi3GetFloat64);
        SYM(h3, fmi3DoStepTYPE, fmi3DoStep);
        SYM(h3, fmi3ActivateModelPartitionTYPE, fmi3ActivateModelPartition);
        SYM(h2, fmi2InstantiateTYPE, fmi2Instantiate);
        SYM(h2, fmi2SetupExperimentTYPE, fmi2SetupExperiment);
        SYM(h2, fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode);
        SYM(h2, fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode);
        SYM(h2, fmi2SetRealTYPE, fmi2SetReal);
        SYM(h2, fmi2GetRealTYPE, fmi2GetReal);
        SYM(h2, fmi2DoStepTYPE, fmi2DoStep);
        fmi3Instance both[2];
        fmi3ValueReference om = 2000;
        fmi2ValueReference om2[8];
        se = fmi3InstantiateScheduledExecution("se", argv[3], "", 0, 0, NULL, logger3, NULL, NULL,
                                               NULL);
        cs = fmi3InstantiateCoSimulation("cs", argv[3], "", 0, 0, 0, 0, NULL, 0, NULL, logger3,
                                         NULL);
        c2 = fmi2Instantiate("cs2", fmi2CoSimulation, argv[3], "", &cb2, 0, 0);
        if (!se || !cs || !c2) return 3;
        both[0] = se, both[1] = cs;
        for (i = 0; i < 2; i++) {
            fmi3EnterInitializationMode(both[i], 0, 0, 0.0, 0, 0);
            for (k = 0; k < nv; k++) fmi3SetFloat64(both[i], &vrs[k], 1, vals[k], ns_[k]);
            if (fmi3ExitInitializationMode(both[i]) > fmi3Warning) return 3;
        }
        fmi2SetupExperiment(c2, 0, 0, 0.0, 0, 0);
        fmi2EnterInitializationMode(c2);
        for (k = 0; k < nv; k++) {
            fmi2ValueReference e[64];
            for (i = 0; i < (int)ns_[k]; i++) e[i] = vrs[k] + (unsigned)i;
            fmi2SetReal(c2, e, ns_[k], vals[k]);
        }
        if (fmi2ExitInitializationMode(c2) > fmi2Warning) return 3;
        n = rounds * samples;
        for (i = 0; i < 3; i++) cost[i] = (double *)malloc((size_t)n * sizeof(double));
        for (k = 0; k < warmup; k++) {
            double t = k * 0.002;
            if (fmi3ActivateModelPartition(se, 5000, t) || fmi2DoStep(c2, t, 0.002, 1) ||
                fmi3DoStep(cs, t, 0.002, 1, &b1, &b2, &b3, &last))
                return 4;
        }
        for (r = 0, i = 0; r < rounds; r++) {
            int k0 = warmup + r * samples, j;
            for (j = 0; j < samples; j++) {
                double t = (k0 + j) * 0.002, a = now_ns();
                if (fmi3ActivateModelPartition(se, 5000, t)) return 4;
                cost[0][i + j] = now_ns() - a;
            }
            for (j = 0; j < samples; j++) {
                double t = (k0 + j) * 0.002, a = now_ns();
                if (fmi3DoStep(cs, t, 0.002, 1, &b1, &b2, &b3, &last)) return 4;
                cost[1][i + j] = now_ns() - a;
            }
            for (j = 0; j < samples; j++) {
                double t = (k0 + j) * 0.002, a = now_ns();
                if (fmi2DoStep(c2, t, 0.002, 1)) return 4;
                cost[2][i + j] = now_ns() - a;
            }
            i += samples;
        }
        report("se", cost[0], n);
        report("cs3", cost[1], n);
        report("cs2", cost[2], n);
        for (i = 0; i < 8; i++) om2[i] = 2000u + (unsigned)i;
        fmi3GetFloat64(se, &om, 1, w3, 8);
        fmi2GetReal(c2, om2, 8, w2);
        same = memcmp(w3, w2, sizeof w3) == 0;
        fmi3GetFloat64(cs, &om, 1, w2, 8);
        same = same && memcmp(w3, w2, sizeof w3) == 0;
        printf("same %d\n", same);
    }
    return 0;
}
"""


def native(tmp: Path, inputs: dict[str, list[float]], args) -> dict[str, tuple] | None:
    """The three interfaces timed by the C harness: name -> (mean, median, p99) in us, and
    "same" -> rotor commands bit-identical; None without a C compiler."""
    cc = os.environ.get("CC") or shutil.which("cc")
    if cc is None:
        return None
    u3, u2 = tmp / "ctrl3", tmp / "ctrl2"
    md = read_model_description(str(artifact("controller", "fmi3/FullPoseController.fmu")))
    measured = {v.name: v.valueReference for v in md.modelVariables if v.causality == "input"}
    src, exe = tmp / "harness.c", tmp / "harness"
    src.write_text(HARNESS)
    build = subprocess.run([cc, "-O2", "-std=c99", "-D_POSIX_C_SOURCE=199309L",
                            "-I", str(u2 / "sources"), "-I", str(u3 / "sources"), str(src),
                            "-o", str(exe), "-ldl"], capture_output=True, text=True)
    if build.returncode != 0:
        print(f"native harness not built: {build.stderr.strip()[:300]}")
        return None
    lines = [f"{measured[n]} {len(v)} " + " ".join(repr(x) for x in v)
             for n, v in [*inputs.items(), ("pos_ref", POS0)] if n in measured]
    so = "binaries/{}/FullPoseController.so"
    run = subprocess.run([str(exe), str(u3 / so.format("x86_64-linux")),
                          str(u2 / so.format("linux64")), md.guid, str(args.rounds),
                          str(args.samples), str(args.warmup)], input="\n".join(lines),
                         capture_output=True, text=True)
    if run.returncode != 0:
        print(f"native harness failed ({run.returncode}): {run.stderr.strip()[:300]}")
        return None
    out: dict[str, tuple] = {}
    for line in run.stdout.split("\n"):
        parts = line.split()
        if len(parts) == 4:
            out[parts[0]] = tuple(float(x) for x in parts[1:])
        elif len(parts) == 2 and parts[0] == "same":
            out["same"] = (parts[1] == "1",)
    return out


def main() -> None:
    """Parse the options, run, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=int, default=500, help="timed samples per round")
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--no-native", action="store_true", help="skip the C harness")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        inputs = hover_inputs(tmp)
        ctrls = {
            "FMI 3.0 SE  fmi3ActivateModelPartition": Fmi3Controller(tmp, True, inputs),
            "FMI 3.0 CS  fmi3DoStep(t, Ts)": Fmi3Controller(tmp, False, inputs),
            "FMI 2.0 CS  fmi2DoStep(t, Ts)": Fmi2Controller(tmp, inputs),
        }
        se = next(iter(ctrls.values())).fmu
        get, inst = se.dll.fmi3GetFloat64, se.component
        none = ctypes.POINTER(ctypes.c_uint32)()
        nothing = ctypes.POINTER(ctypes.c_double)()
        floor = "(floor: fmi3GetFloat64 of nothing)"
        for c in ctrls.values():
            timed(c.step, 0, args.warmup)
        cost: dict[str, list[np.ndarray]] = {name: [] for name in [*ctrls, floor]}
        k = args.warmup
        for _ in range(args.rounds):
            for name, c in ctrls.items():
                cost[name].append(timed(c.step, k, args.samples))
            cost[floor].append(timed(lambda t: get(inst, none, 0, nothing, 0), k,
                                     args.samples))
            k += args.samples
        commands = [c.commands() for c in ctrls.values()]
        same = all(x.tobytes() == commands[0].tobytes() for x in commands)
        c_cost = None if args.no_native else native(tmp, inputs, args)
    us = {name: np.concatenate(v) / 1e3 for name, v in cost.items()}
    n = args.rounds * args.samples
    print(f"FullPoseController, hover at {POS0}, {n} timed samples per interface "
          f"({args.rounds} interleaved rounds of {args.samples}, after {args.warmup}); "
          f"pid {os.getpid()}")
    print(f"{'interface':<42} {'mean us':>9} {'median us':>10} {'p99 us':>9}")
    for name, v in us.items():
        print(f"{name:<42} {v.mean():9.2f} {np.median(v):10.2f} {np.percentile(v, 99):9.2f}")
    names = list(us)
    se = us[names[0]]
    for other in names[1:3]:
        o = us[other]
        print(f"SE / {other.split('  ')[0]}: {se.mean() / o.mean():.3f} (mean), "
              f"{np.median(se) / np.median(o):.3f} (median), "
              f"{np.percentile(se, 99) / np.percentile(o, 99):.3f} (p99)")
    print(f"rotor commands of the three bit-identical after {k} samples: {same}")
    if c_cost is None:
        return
    print(f"\nfrom C (dlopen, clock_gettime around each call; {n} samples per interface)")
    print(f"{'interface':<42} {'mean us':>9} {'median us':>10} {'p99 us':>9}")
    for key, name in zip(("se", "cs3", "cs2"), names[:3], strict=True):
        mean, median, p99 = c_cost[key]
        print(f"{name:<42} {mean:9.2f} {median:10.2f} {p99:9.2f}")
    for key, name in (("cs3", names[1]), ("cs2", names[2])):
        print(f"SE / {name.split('  ')[0]}: {c_cost['se'][0] / c_cost[key][0]:.3f} (mean), "
              f"{c_cost['se'][1] / c_cost[key][1]:.3f} (median), "
              f"{c_cost['se'][2] / c_cost[key][2]:.3f} (p99)")
    print(f"rotor commands of the three bit-identical: {c_cost.get('same', (False,))[0]}")


if __name__ == "__main__":
    main()
