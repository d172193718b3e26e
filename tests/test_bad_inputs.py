"""Every bad input a new user might type, on every command: one line ``sdr-di: error: ...``,
exit status 2, no traceback, no output file left (issue 12 item 4).

The CLI runs in-process (``sdr_di.cli.main``). ``CASES`` is a table of (id, argv); ``{d}`` in
an argument is the shared work folder made by :func:`make_workdir` (a small generated set in
``{d}/set``, broken sidecars, scenarios and experiment folders). The folder's file list is
compared before and after each case: a case that leaves a file (or a folder) behind fails.
"""

from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import pytest

from sdr_di.cli import main
from sdr_di.scenario import DEFAULT_SCENARIO, REPO_ROOT

#: Arguments of a small valid set (0.02 s at 2.5 MHz): cheap to generate, and the base of the
#: generate cases (so a case that wrongly starts work finishes quickly).
G = ["generate", "--no-progress", "--fs", "2.5e6"]
GD = [*G, "--duration", "0.02"]
LC = ["lc"]
EXP = "noise-mismatch"

CASES: list[tuple] = [
    # -- argument parser ---------------------------------------------------------------------
    ("no-command", []),
    ("unknown-command", ["frobnicate"]),
    ("unknown-option", ["generate", "--frobnicate"]),
    ("run-no-file", ["run"]),
    ("run-bad-mode", ["run", "{d}/set/s.bin", "--mode", "vector"]),
    ("generate-duration-text", [*G, "--duration", "abc"]),
    ("generate-seed-float", [*GD, "--seed", "1.5"]),
    ("campaign-no-runs", ["campaign", EXP]),
    ("campaign-runs-text", ["campaign", EXP, "--runs", "many"]),
    ("lc-r-window-two-values", [*LC, "--r-window", "1", "2"]),
    ("report-no-dir", ["report"]),
    # -- generate ----------------------------------------------------------------------------
    ("generate-duration-0", [*G, "--duration", "0", "--out", "{d}/o"]),
    ("generate-duration-neg", [*G, "--duration", "-1", "--out", "{d}/o"]),
    ("generate-duration-nan", [*G, "--duration", "nan", "--out", "{d}/o"]),
    ("generate-duration-inf", [*G, "--duration", "inf", "--out", "{d}/o"]),
    ("generate-duration-1e-9", [*G, "--duration", "1e-9", "--out", "{d}/o"]),
    ("generate-duration-1ms", [*G, "--duration", "0.001", "--out", "{d}/o"]),
    ("generate-duration-4ms", [*G, "--duration", "0.004", "--out", "{d}/o"]),
    ("generate-duration-9ms", [*G, "--duration", "0.009", "--out", "{d}/o"]),
    ("generate-fs-0", ["generate", "--no-progress", "--duration", "0.02", "--fs", "0",
                       "--out", "{d}/o"]),
    ("generate-fs-neg", ["generate", "--no-progress", "--duration", "0.02", "--fs", "-2.5e6",
                         "--out", "{d}/o"]),
    ("generate-fs-nan", ["generate", "--no-progress", "--duration", "0.02", "--fs", "nan",
                         "--out", "{d}/o"]),
    ("generate-fs-1khz", ["generate", "--no-progress", "--duration", "0.02", "--fs", "1e3",
                          "--out", "{d}/o"]),
    ("generate-if-nan", [*GD, "--if", "nan", "--out", "{d}/o"]),
    ("generate-if-above-fs", [*GD, "--if", "3e6", "--out", "{d}/o"]),
    ("generate-format-bogus", [*GD, "--format", "int3", "--out", "{d}/o"]),
    ("generate-real-no-if", [*GD, "--format", "real_int8", "--out", "{d}/o"]),
    ("generate-bits-0", [*GD, "--bits", "0", "--out", "{d}/o"]),
    ("generate-bits-99", [*GD, "--bits", "99", "--out", "{d}/o"]),
    ("generate-cn0-nan", [*GD, "--cn0", "nan", "--out", "{d}/o"]),
    ("generate-cn0-neg", [*GD, "--cn0", "-500", "--out", "{d}/o"]),
    ("generate-cn0-200", [*GD, "--cn0", "200", "--out", "{d}/o"]),
    ("generate-prn-c99", [*GD, "--prn", "C99", "--out", "{d}/o"]),
    ("generate-prn-text", [*GD, "--prn", "GPS", "--out", "{d}/o"]),
    ("generate-prn-empty", [*GD, "--prn", ",", "--out", "{d}/o"]),
    ("generate-seed-neg", [*GD, "--seed", "-1", "--out", "{d}/o"]),
    ("generate-scenario-missing", [*GD, "--scenario", "{d}/nope.toml", "--out", "{d}/o"]),
    ("generate-scenario-dir", [*GD, "--scenario", "{d}", "--out", "{d}/o"]),
    ("generate-scenario-not-toml", [*GD, "--scenario", "{d}/bad.toml", "--out", "{d}/o"]),
    ("generate-scenario-wrong-type", [*GD, "--scenario", "{d}/types.toml", "--out", "{d}/o"]),
    ("generate-scenario-binary", [*GD, "--scenario", "{d}/set/s.bin", "--out", "{d}/o"]),
    ("generate-scenario-empty", [*GD, "--scenario", "{d}/empty.toml", "--out", "{d}/o"]),
    ("generate-ephemeris-missing", [*GD, "--ephemeris", "{d}/nope.rnx", "--out", "{d}/o"]),
    ("generate-ephemeris-binary", [*GD, "--ephemeris", "{d}/set/s.bin", "--out", "{d}/o"]),
    ("generate-ephemeris-csv", [*GD, "--ephemeris", "{d}/set/s_imu.csv", "--out", "{d}/o"]),
    # a BDS record dated before the BDT epoch (year "0020" for "2020": a ValueError from the
    # time conversion escaped the parser, found by tests/test_fuzz_parsers.py)
    ("generate-ephemeris-year-0020", [*GD, "--ephemeris", "{d}/y0020_nav.rnx", "--out",
                                      "{d}/o"]),
    ("generate-name-empty", [*GD, "--name", "", "--out", "{d}/o"]),
    ("generate-name-slash", [*GD, "--name", "a/b", "--out", "{d}/o"]),
    ("generate-name-dot", [*GD, "--name", ".hidden", "--out", "{d}/o"]),
    ("generate-out-file", [*GD, "--out", "{d}/afile"]),
    ("generate-out-under-file", [*GD, "--out", "{d}/afile/sub"]),
    # -- run ---------------------------------------------------------------------------------
    ("run-missing-bin", ["run", "{d}/nope.bin"]),
    ("run-missing-json", ["run", "{d}/nope.json"]),
    ("run-missing-foreign", ["run", "{d}/nope.bin", "--fs", "2.5e6", "--format", "iq_int8"]),
    ("run-directory", ["run", "{d}"]),
    ("run-no-sidecar", ["run", "{d}/afile"]),
    ("run-sidecar-not-json", ["run", "{d}/set/notjson.json"]),
    ("run-sidecar-list", ["run", "{d}/set/list.json"]),
    ("run-sidecar-string", ["run", "{d}/set/string.json"]),
    ("run-sidecar-rate-text", ["run", "{d}/set/rate_text.json"]),
    ("run-sidecar-rate-neg", ["run", "{d}/set/rate_neg.json"]),
    ("run-sidecar-nsamples-text", ["run", "{d}/set/nsamp_text.json"]),
    ("run-sidecar-nsamples-neg", ["run", "{d}/set/nsamp_neg.json"]),
    ("run-sidecar-start-text", ["run", "{d}/set/start_text.json"]),
    ("run-sidecar-start-week-text", ["run", "{d}/set/week_text.json"]),
    ("run-sidecar-format-number", ["run", "{d}/set/fmt_number.json"]),
    ("run-sidecar-format-bogus", ["run", "{d}/set/fmt_bogus.json"]),
    ("run-sidecar-iffile-number", ["run", "{d}/set/iffile_number.json"]),
    ("run-sidecar-iffile-missing", ["run", "{d}/set/iffile_missing.json"]),
    ("run-sidecar-inverted-text", ["run", "{d}/set/inverted_text.json"]),
    ("run-sidecar-carrier-text", ["run", "{d}/set/carrier_text.json"]),
    ("run-sidecar-schema", ["run", "{d}/set/schema.json"]),
    ("run-mixed-set-bin", ["run", "{d}/mixed/s.bin"]),
    ("run-mixed-set-json", ["run", "{d}/mixed/s.json"]),
    ("run-rate-0", ["run", "{d}/set/s.bin", "--rate", "0"]),
    ("run-rate-neg", ["run", "{d}/set/s.bin", "--rate", "-5"]),
    ("run-rate-nan", ["run", "{d}/set/s.bin", "--rate", "nan"]),
    ("run-rate-inf", ["run", "{d}/set/s.bin", "--rate", "inf"]),
    ("run-prn-c99", ["run", "{d}/set/s.bin", "--prn", "C99"]),
    ("run-prn-text", ["run", "{d}/set/s.bin", "--prn", "L1"]),
    ("run-out-file", ["run", "{d}/set/s.bin", "--out", "{d}/afile"]),
    ("run-foreign-fs-only", ["run", "{d}/foreign/s.bin", "--fs", "2.5e6"]),
    ("run-foreign-fs-0", ["run", "{d}/set/s.bin", "--fs", "0", "--format", "iq_int8"]),
    ("run-foreign-fs-nan", ["run", "{d}/set/s.bin", "--fs", "nan", "--format", "iq_int8"]),
    ("run-foreign-if-nan", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "iq_int8",
                            "--if", "nan"]),
    ("run-foreign-format-bogus", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "int3"]),
    ("run-foreign-empty", ["run", "{d}/empty.bin", "--fs", "2.5e6", "--format", "iq_int8"]),
    ("run-start-week-neg", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "iq_int8",
                            "--start-week", "-1"]),
    ("run-start-week-huge", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "iq_int8",
                             "--start-week", "100000"]),
    ("run-start-sow-neg", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "iq_int8",
                           "--start-sow", "-1"]),
    ("run-start-sow-week-long", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format",
                                 "iq_int8", "--start-sow", "604800"]),
    ("run-start-sow-nan", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--format", "iq_int8",
                           "--start-sow", "nan"]),
    ("run-deep-option-scalar", ["run", "{d}/set/s.bin", "--filter", "ekf"]),
    ("run-deep-filter-bogus", ["run", "{d}/set/s.bin", "--mode", "deep", "--filter", "kf"]),
    ("run-deep-filter-rate-0", ["run", "{d}/set/s.bin", "--mode", "deep", "--filter-rate",
                                "0"]),
    ("run-deep-filter-rate-nan", ["run", "{d}/set/s.bin", "--mode", "deep", "--filter-rate",
                                  "nan"]),
    ("run-deep-filter-rate-7", ["run", "{d}/set/s.bin", "--mode", "deep", "--filter-rate",
                                "7"]),
    ("run-deep-duration-0", ["run", "{d}/set/s.bin", "--mode", "deep", "--duration", "0"]),
    ("run-deep-duration-nan", ["run", "{d}/set/s.bin", "--mode", "deep", "--duration", "nan"]),
    ("run-deep-rate-0", ["run", "{d}/set/s.bin", "--mode", "deep", "--rate", "0"]),
    ("run-deep-imu-missing", ["run", "{d}/set/s.bin", "--mode", "deep", "--imu",
                              "{d}/nope.csv"]),
    ("run-deep-imu-is-truth", ["run", "{d}/set/s.bin", "--mode", "deep", "--imu",
                               "{d}/set/s_truth.csv"]),
    ("run-deep-truth-is-imu", ["run", "{d}/set/s.bin", "--mode", "deep", "--truth",
                               "{d}/set/s_imu.csv"]),
    ("run-deep-ephemeris-binary", ["run", "{d}/set/s.bin", "--mode", "deep", "--ephemeris",
                                   "{d}/set/s.bin"]),
    ("run-deep-mixed-imu", ["run", "{d}/mixed_imu/s.bin", "--mode", "deep"]),
    ("run-deep-companion-missing", ["run", "{d}/noimu/s.bin", "--mode", "deep"]),
    ("run-loose-companion-missing", ["run", "{d}/noimu/s.bin", "--mode", "loose"]),
    ("run-tight-companion-missing", ["run", "{d}/noimu/s.bin", "--mode", "tight"]),
    ("run-loose-no-imu", ["run", "{d}/set/no_imu_file.json", "--mode", "loose"]),
    ("run-tight-no-imu", ["run", "{d}/set/no_imu_file.json", "--mode", "tight"]),
    ("run-loose-imu-too-short", ["run", "{d}/set/s.bin", "--mode", "loose", "--imu",
                                 "{d}/short_imu.csv", "--out", "{d}/o"]),
    ("run-tight-imu-too-short", ["run", "{d}/set/s.bin", "--mode", "tight", "--imu",
                                 "{d}/short_imu.csv", "--out", "{d}/o"]),
    ("run-tight-gnss-rate-3", ["run", "{d}/set/s.bin", "--mode", "tight", "--gnss-rate", "3"]),
    ("run-tight-gnss-rate-nan", ["run", "{d}/set/s.bin", "--mode", "tight", "--gnss-rate",
                                 "nan"]),
    ("run-scalar-gnss-rate", ["run", "{d}/set/s.bin", "--gnss-rate", "5"]),
    ("run-loose-nco-latency", ["run", "{d}/set/s.bin", "--mode", "loose", "--nco-latency", "1"]),
    ("run-deep-nco-latency-2", ["run", "{d}/set/s.bin", "--mode", "deep", "--nco-latency",
                                "2"]),
    ("run-pll-bw-0", ["run", "{d}/set/s.bin", "--pll-bw", "0"]),
    ("run-pll-bw-unstable", ["run", "{d}/set/s.bin", "--pll-bw", "40"]),
    ("run-deep-pll-bw-unstable", ["run", "{d}/set/s.bin", "--mode", "deep", "--pll-bw",
                                  "26"]),
    ("run-deep-iono-wait-negative", ["run", "{d}/set/s.bin", "--mode", "deep", "--iono-wait",
                                     "-1"]),
    ("run-scalar-iono-wait", ["run", "{d}/set/s.bin", "--iono-wait", "0"]),
    # -- acquire -----------------------------------------------------------------------------
    ("acquire-no-file", ["acquire"]),
    ("acquire-missing", ["acquire", "{d}/nope.bin"]),
    ("acquire-directory", ["acquire", "{d}"]),
    ("acquire-coherent-0", ["acquire", "{d}/set/s.bin", "--coherent-ms", "0"]),
    ("acquire-coherent-text", ["acquire", "{d}/set/s.bin", "--coherent-ms", "1.5"]),
    ("acquire-noncoherent-0", ["acquire", "{d}/set/s.bin", "--noncoherent", "0"]),
    ("acquire-pfa-2", ["acquire", "{d}/set/s.bin", "--pfa", "2"]),
    ("acquire-pfa-nan", ["acquire", "{d}/set/s.bin", "--pfa", "nan"]),
    ("acquire-doppler-range-neg", ["acquire", "{d}/set/s.bin", "--doppler-range", "-1"]),
    ("acquire-doppler-center-nan", ["acquire", "{d}/set/s.bin", "--doppler-center", "nan"]),
    ("acquire-prn-c99", ["acquire", "{d}/set/s.bin", "--prn", "C99"]),
    ("acquire-out-file", ["acquire", "{d}/set/s.bin", "--out", "{d}/afile"]),
    ("acquire-rfch-3", ["acquire", "{d}/set/s.bin", "--rfch", "3"]),
    ("acquire-sidecar-list", ["acquire", "{d}/set/list.json"]),
    ("acquire-start-week-neg", ["acquire", "{d}/set/s.bin", "--fs", "2.5e6", "--format",
                                "iq_int8", "--start-week", "-3"]),
    ("acquire-start-sow-nan", ["acquire", "{d}/set/s.bin", "--fs", "2.5e6", "--format",
                               "iq_int8", "--start-sow", "nan"]),
    ("acquire-fs-inf", ["acquire", "{d}/set/s.bin", "--fs", "inf", "--format", "iq_int8"]),
    ("acquire-mixed-set", ["acquire", "{d}/mixed/s.bin"]),
    # -- more run / generate a new user tries ------------------------------------------------
    ("run-if-nan-sidecar", ["run", "{d}/set/s.bin", "--if", "nan"]),
    ("run-imu-only-scalar", ["run", "{d}/set/s.bin", "--imu", "{d}/set/s_imu.csv"]),
    ("run-align-bogus", ["run", "{d}/set/s.bin", "--mode", "deep", "--align", "ins"]),
    ("run-sidecar-week-huge", ["run", "{d}/set/week_huge.json"]),
    ("run-sidecar-sow-neg", ["run", "{d}/set/sow_neg.json"]),
    ("run-sidecar-null-carrier", ["run", "{d}/set/carrier_null.json"]),
    ("generate-cn0-text", [*GD, "--cn0", "strong", "--out", "{d}/o"]),
    ("generate-ephemeris-dir", [*GD, "--ephemeris", "{d}", "--out", "{d}/o"]),
    ("generate-scenario-unknown-key", [*GD, "--scenario", "{d}/motion_str.toml", "--out",
                                      "{d}/o"]),
    # -- lc ----------------------------------------------------------------------------------
    ("lc-filter-bogus", [*LC, "--filter", "kalman"]),
    ("lc-duration-0", [*LC, "--duration", "0"]),
    ("lc-duration-nan", [*LC, "--duration", "nan"]),
    ("lc-duration-short", [*LC, "--duration", "0.5"]),
    ("lc-q-scale-0", [*LC, "--q-scale", "0"]),
    ("lc-q-scale-nan", [*LC, "--q-scale", "nan"]),
    ("lc-r-scale-neg", [*LC, "--r-scale", "-1"]),
    ("lc-r-window-reversed", [*LC, "--r-window", "5", "2", "10"]),
    ("lc-r-window-nan", [*LC, "--r-window", "1", "2", "nan"]),
    ("lc-imu-only", [*LC, "--imu", "{d}/set/s_imu.csv"]),
    ("lc-imu-missing", [*LC, "--imu", "{d}/nope.csv", "--truth", "{d}/set/s_truth.csv"]),
    ("lc-imu-swapped", [*LC, "--imu", "{d}/set/s_truth.csv", "--truth", "{d}/set/s_imu.csv"]),
    ("lc-imu-too-short", [*LC, "--imu", "{d}/set/s_imu.csv", "--truth",
                          "{d}/set/s_truth.csv"]),
    ("lc-out-file", [*LC, "--out", "{d}/afile"]),
    # -- assumptions and the truth oscillator (issue 14) ---------------------------------------
    ("lc-assume-unknown-grade", [*LC, "--assume", "{d}/assume_grade.toml"]),
    ("lc-assume-negative-h", [*LC, "--assume", "{d}/assume_neg_h.toml"]),
    ("lc-assume-unknown-key", [*LC, "--assume", "{d}/assume_key.toml"]),
    ("lc-assume-missing", [*LC, "--assume", "{d}/nope.toml"]),
    ("lc-assume-oscillator", [*LC, "--assume", "{d}/assume_osc.toml"]),
    ("run-scalar-assume", ["run", "{d}/set/s.bin", "--assume", "{d}/assume_osc.toml"]),
    ("run-deep-assume-bad", ["run", "{d}/set/s.bin", "--mode", "deep", "--no-progress",
                             "--assume", "{d}/assume_neg_h.toml", "--out", "{d}/o"]),
    # -- SigMF recordings (issue 28) -----------------------------------------------------------
    ("run-sigmf-datatype-cu8", ["run", "{d}/sigmf/cu8.sigmf-meta"]),
    ("acquire-sigmf-datatype-big-endian", ["acquire", "{d}/sigmf/ci16_be.sigmf-data"]),
    ("run-sigmf-gps-l1-centre", ["run", "{d}/sigmf/l1.sigmf-meta"]),
    ("acquire-sigmf-b3i-0.7mhz-off", ["acquire", "{d}/sigmf/off.sigmf-meta"]),
    ("run-sigmf-two-frequencies", ["run", "{d}/sigmf/two.sigmf-meta", "--mode", "deep"]),
    ("run-sigmf-invalid-meta", ["run", "{d}/sigmf/invalid.sigmf-meta"]),
    ("acquire-sigmf-no-frequency", ["acquire", "{d}/sigmf/nofreq"]),
    ("run-sigmf-archive", ["run", "{d}/sigmf/rec.sigmf"]),
    ("generate-sigmf-iq-int4", [*GD, "--format", "iq_int4", "--sigmf", "--out", "{d}/o"]),
    ("generate-sigmf-real-if-0.2mhz", [*GD, "--format", "real_int8", "--if", "0.2e6",
                                       "--sigmf", "--out", "{d}/o"]),
    ("generate-assume", [*GD, "--assume", "{d}/assume_osc.toml", "--out", "{d}/o"]),
    ("generate-oscillator-preset", [*GD, "--scenario", "{d}/osc_preset.toml", "--out",
                                   "{d}/o"]),
    # -- interference and the jamming experiment (issue 15) ----------------------------------
    ("generate-imu-unknown-grade", [*GD, "--scenario", "{d}/imu_grade.toml", "--out", "{d}/o"]),
    ("generate-imu-negative-sigma", [*GD, "--scenario", "{d}/imu_neg.toml", "--out", "{d}/o"]),
    ("generate-atmosphere-unknown-truth", [*GD, "--scenario", "{d}/atm_truth.toml", "--out",
                                           "{d}/o"]),
    ("generate-atmosphere-negative-sigma", [*GD, "--scenario", "{d}/atm_neg.toml", "--out",
                                            "{d}/o"]),
    ("generate-jammer-unknown-type", [*GD, "--scenario", "{d}/jam_type.toml", "--out", "{d}/o"]),
    ("generate-jammer-negative-bandwidth", [*GD, "--scenario", "{d}/jam_bw.toml", "--out",
                                           "{d}/o"]),
    ("generate-jammer-js-out-of-range", [*GD, "--scenario", "{d}/jam_js.toml", "--out",
                                        "{d}/o"]),
    ("generate-jammer-band-outside", [*GD, "--scenario", "{d}/jam_band.toml", "--out", "{d}/o"]),
    ("campaign-jamming-bits", ["campaign", "jamming", "--runs", "2", "--param", "bits=5",
                               "--out", "{d}/c"]),
    ("lc-out-under-file", [*LC, "--out", "{d}/afile/sub"]),
    ("lc-scenario-missing", [*LC, "--scenario", "{d}/nope.toml"]),
    ("lc-scenario-not-toml", [*LC, "--scenario", "{d}/bad.toml"]),
    ("lc-seed-neg", [*LC, "--seed", "-3"]),
    # -- campaign / robustness ---------------------------------------------------------------
    ("campaign-unknown-experiment", ["campaign", "frobnicate", "--runs", "2"]),
    ("campaign-runs-0", ["campaign", EXP, "--runs", "0", "--out", "{d}/c"]),
    ("campaign-runs-neg", ["campaign", EXP, "--runs", "-2", "--out", "{d}/c"]),
    ("campaign-workers-0", ["campaign", EXP, "--runs", "2", "--workers", "0", "--out",
                            "{d}/c"]),
    ("campaign-seed-neg", ["campaign", EXP, "--runs", "2", "--seed", "-1", "--out", "{d}/c"]),
    ("campaign-duration-nan", ["campaign", EXP, "--runs", "2", "--duration", "nan", "--out",
                               "{d}/c"]),
    ("campaign-param-no-equals", ["campaign", EXP, "--runs", "2", "--param", "case", "--out",
                                  "{d}/c"]),
    ("campaign-param-unknown", ["campaign", EXP, "--runs", "2", "--param", "speed=3", "--out",
                                "{d}/c"]),
    ("campaign-param-case-bogus", ["campaign", EXP, "--runs", "2", "--param", "case=z",
                                   "--out", "{d}/c"]),
    ("campaign-param-filters-bogus", ["campaign", EXP, "--runs", "2", "--param",
                                      "filters=kalman", "--out", "{d}/c"]),
    ("campaign-param-scenario-missing", ["campaign", EXP, "--runs", "2", "--param",
                                         "scenario={d}/nope.toml", "--out", "{d}/c"]),
    ("campaign-out-file", ["campaign", EXP, "--runs", "2", "--out", "{d}/afile"]),
    ("robustness-unknown-experiment", ["robustness", "frobnicate"]),
    ("robustness-scenario-missing", ["robustness", EXP, "--param", "scenario={d}/nope.toml",
                                     "--out", "{d}/r"]),
    ("robustness-scenario-not-toml", ["robustness", EXP, "--param", "scenario={d}/bad.toml",
                                      "--out", "{d}/r"]),
    ("robustness-scenario-wrong-type", ["robustness", EXP, "--param",
                                        "scenario={d}/types.toml", "--out", "{d}/r"]),
    ("robustness-scenario-number", ["robustness", EXP, "--param", "scenario=12", "--out",
                                    "{d}/r"]),
    ("robustness-param-bool-text", ["robustness", EXP, "--param", "plots=maybe", "--out",
                                    "{d}/r"]),
    ("robustness-filters-bogus", ["robustness", EXP, "--param", "filters=ekf,kalman",
                                  "--out", "{d}/r"]),
    ("robustness-duration-0", ["robustness", EXP, "--duration", "0", "--out", "{d}/r"]),
    ("robustness-out-file", ["robustness", EXP, "--out", "{d}/afile"]),
    ("robustness-outage-bogus", ["robustness", "outage", "--param", "outages=5,x", "--out",
                                 "{d}/r"]),
    ("robustness-count-bogus", ["robustness", "count-change", "--param", "counts=7,0,7",
                                "--out", "{d}/r"]),
    ("robustness-weak-modes-bogus", ["robustness", "weak-signal", "--param", "modes=vector",
                                     "--out", "{d}/r"]),
    # -- report ------------------------------------------------------------------------------
    ("report-missing-dir", ["report", "{d}/nope"]),
    ("report-file", ["report", "{d}/afile"]),
    ("report-empty-dir", ["report", "{d}/emptydir"]),
    ("report-campaign-corrupt", ["report", "{d}/camp_corrupt"]),
    ("report-campaign-list", ["report", "{d}/camp_list"]),
    ("report-result-corrupt", ["report", "{d}/res_corrupt"]),
    ("report-result-wrong-types", ["report", "{d}/res_types"]),
    # -- issue 28: flags against the sidecar, messages that name the flag --------------------
    ("run-sidecar-format-contradicted", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--if", "0",
                                         "--format", "real_int8"]),
    ("run-sidecar-fs-contradicted", ["run", "{d}/set/s.bin", "--fs", "5e6", "--format",
                                     "iq_int8"]),
    ("run-sidecar-if-contradicted", ["run", "{d}/set/s.bin", "--if", "1e3"]),
    ("run-sidecar-inverted-contradicted", ["run", "{d}/set/s.bin", "--inverted"]),
    ("run-sidecar-start-contradicted", ["run", "{d}/set/s.bin", "--start-week", "3"]),
    ("acquire-sidecar-format-contradicted", ["acquire", "{d}/set/s.bin", "--fs", "2.5e6",
                                             "--format", "real_int8"]),
    ("run-truncated-with-flags", ["run", "{d}/trunc/s.bin", "--fs", "2.5e6", "--format",
                                  "iq_int8"]),
    ("run-ignore-sidecar-json", ["run", "{d}/set/s.json", "--ignore-sidecar", "--fs", "2.5e6",
                                 "--format", "iq_int8"]),
    ("run-foreign-format-check", ["run", "{d}/foreign/s.bin", "--fs", "2.5e6", "--format",
                                  "iq_int16"]),
    ("generate-if-above-fs-real", ["generate", "--no-progress", "--duration", "0.02", "--fs",
                                   "4.5e6", "--if", "20e6", "--format", "real_int16",
                                   "--out", "{d}/o"]),
    ("generate-real-format-no-if", [*GD, "--format", "real_int16", "--out", "{d}/o"]),
    # -- issue 28: runs that end without a fix: exit 1, one line, no folder left -------------
    ("run-no-satellite", ["run", "{d}/set/s.bin", "--prn", "C40", "--no-progress"], 1),
    ("run-wrong-format-implausible", ["run", "{d}/set/s.bin", "--fs", "2.5e6", "--if", "0",
                                      "--format", "real_int8", "--ignore-sidecar",
                                      "--no-progress"], 1),
    ("run-deep-too-short-for-handover", ["run", "{d}/set/s.bin", "--mode", "deep",
                                         "--no-progress"], 1),
    ("study-cell-unknown-truth-key", ["study", "{d}/study_typo.toml", "--out", "{d}/st"]),
    # -- issue 49: nothing lost, nothing misleading --------------------------------------------
    ("run-output-is-the-ephemeris", ["run", "{d}/navset/s.bin", "--ephemeris",
                                     "{d}/navset/s_nav.rnx", "--out", "{d}/navset",
                                     "--no-progress"]),
    ("generate-output-is-the-scenario", [*GD, "--scenario", "{d}/navset/x.json", "--name", "x",
                                         "--out", "{d}/navset"]),
    ("lc-output-is-the-scenario", [*LC, "--scenario", "{d}/navset/default_lc_ekf.csv",
                                   "--duration", "2", "--out", "{d}/navset"]),
    ("generate-out-name-300-chars", [*GD, "--out", "{d}/" + "x" * 300]),
    ("generate-name-250-chars", [*GD, "--name", "n" * 250, "--out", "{d}/o"]),
    ("run-out-name-300-chars", ["run", "{d}/set/s.bin", "--out", "{d}/" + "x" * 300]),
    ("run-path-5kb", ["run", "{d}/" + "/".join(["y" * 200] * 25) + "/s.bin"]),
    ("acquire-out-5kb", ["acquire", "{d}/set/s.bin", "--out",
                         "{d}/" + "/".join(["y" * 200] * 25)]),
    ("lc-out-name-300-chars", [*LC, "--duration", "2", "--out", "{d}/" + "x" * 300]),
    ("report-dir-name-300-chars", ["report", "{d}/" + "x" * 300]),
    ("generate-scenario-nested-3000", [*GD, "--scenario", "{d}/nested.toml", "--out", "{d}/o"]),
    ("study-spec-nested-3000", ["study", "{d}/nested.toml", "--out", "{d}/st"]),
    ("lc-assume-nested-3000", [*LC, "--assume", "{d}/nested.toml"]),
    ("generate-duration-1e9-disk", [*G, "--duration", "1e9", "--out", "{d}/o"]),
    ("lc-duration-1e9", [*LC, "--duration", "1e9"]),
    ("study-million-cells", ["study", "{d}/study_big.toml", "--out", "{d}/st"]),
    ("study-runs-beyond-limit", ["study", "{d}/study_one.toml", "--runs", "20000", "--out",
                                 "{d}/st"]),
    ("acquire-text-as-iq-int8", ["acquire", "{d}/text.bin", "--fs", "2.5e6", "--format",
                                 "iq_int8"]),
    ("acquire-constant-bytes", ["acquire", "{d}/zeros.bin", "--fs", "2.5e6", "--format",
                                "iq_int8"]),
    ("acquire-periodic-pattern", ["acquire", "{d}/pattern.bin", "--fs", "2.5e6", "--format",
                                  "iq_int8"]),
    ("run-sidecar-duplicate-key", ["run", "{d}/set/dup_key.json"]),
    ("run-sidecar-rate-1e308", ["run", "{d}/set/rate_huge.json"]),
    ("acquire-sidecar-rate-vs-n-samples", ["acquire", "{d}/set/rate_vs_n.json"]),
    ("run-sidecar-if-outside-band", ["run", "{d}/set/if_out.json"]),
    ("study-bad-spec-with-plugin", ["study", "{d}/study_plugin.toml", "--out", "{d}/st"]),
]

#: Exit status of a case: 2 (bad input) unless its third element says otherwise (1: a run
#: that went through but ended without a fix, docs/errors.md).
def case_status(case: tuple) -> int:
    return case[2] if len(case) > 2 else 2


def _sidecar_variants(set_dir: Path) -> None:
    meta = json.loads((set_dir / "s.json").read_text())

    def put(name: str, **kw) -> None:
        m = {**meta, **kw}
        (set_dir / name).write_text(json.dumps(m))

    (set_dir / "notjson.json").write_text("{sampling_rate_hz: 25e6")
    (set_dir / "list.json").write_text(json.dumps([meta]))
    (set_dir / "string.json").write_text(json.dumps("s.bin"))
    put("rate_text.json", sampling_rate_hz="fast")
    put("rate_neg.json", sampling_rate_hz=-2.5e6)
    put("nsamp_text.json", n_samples="many")
    put("nsamp_neg.json", n_samples=-5)
    put("start_text.json", start="yesterday")
    put("week_text.json", start={**meta["start"], "week": "755"})
    put("fmt_number.json", sample_format=8)
    put("fmt_bogus.json", sample_format="int3")
    put("iffile_number.json", if_file=12)
    put("iffile_missing.json", if_file="gone.bin")
    put("inverted_text.json", spectrum_inverted="no")
    put("carrier_text.json", carrier_hz="B3I")
    put("schema.json", schema="sdr-di-if/0")
    put("week_huge.json", start={**meta["start"], "week": 123456})
    put("sow_neg.json", start={**meta["start"], "sow": -1.0})
    put("carrier_null.json", carrier_hz=None)
    put("rate_huge.json", sampling_rate_hz=1e308)
    put("rate_vs_n.json", sampling_rate_hz=5e6)
    put("if_out.json", if_hz=5e6)
    (set_dir / "dup_key.json").write_text((set_dir / "s.json").read_text().replace(
        '"sampling_rate_hz":', '"sampling_rate_hz": 5000000.0, "sampling_rate_hz":', 1))
    (set_dir / "no_imu_file.json").write_text(
        json.dumps({k: v for k, v in meta.items() if k != "imu_file"}))


def make_workdir(d: Path, generated: Path) -> None:
    """Fill ``d`` with the inputs the cases name; ``generated`` holds a complete small set."""
    shutil.copytree(generated, d / "set")
    _sidecar_variants(d / "set")
    # a newer, longer .bin beside the old sidecar, IMU and truth (an interrupted re-generation)
    shutil.copytree(generated, d / "mixed")
    with open(d / "mixed" / "s.bin", "ab") as fh:
        fh.write(b"\x01" * 1000)
    shutil.copytree(generated, d / "mixed_imu")
    imu = d / "mixed_imu" / "s_imu.csv"
    imu.write_text(imu.read_text().replace("# rate_hz: 200.0", "# rate_hz: 200.0\n# x: y"))
    shutil.copytree(generated, d / "noimu")
    (d / "noimu" / "s_imu.csv").unlink()
    lines = (d / "set" / "s_imu.csv").read_text().splitlines(keepends=True)
    rows = [ln for ln in lines if ln[:1].isdigit()]      # an IMU record shorter than the IF
    (d / "short_imu.csv").write_text(
        "".join(ln for ln in lines if not ln[:1].isdigit()) + "".join(rows[:2]))
    (d / "empty.bin").write_bytes(b"")
    nav = gzip.decompress((REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
                          .read_bytes()).decode("latin-1").splitlines(keepends=True)
    k = next(i for i, ln in enumerate(nav) if ln[:1] == "C" and ln[3:9] == " 2020 ")
    nav[k] = nav[k][:3] + " 0020 " + nav[k][9:]
    (d / "y0020_nav.rnx").write_text("".join(nav), encoding="latin-1")
    (d / "foreign").mkdir()                      # the IF file alone, without its sidecar
    shutil.copy(generated / "s.bin", d / "foreign" / "s.bin")
    shutil.copytree(generated, d / "trunc")      # an IF file cut short beside its sidecar
    data = (d / "trunc" / "s.bin").read_bytes()
    (d / "trunc" / "s.bin").write_bytes(data[:len(data) // 2])
    (d / "afile").write_text("not a folder\n")
    _issue49_inputs(d, generated)
    (d / "bad.toml").write_text("[scenario\nname = 'x'\n")
    (d / "empty.toml").write_text("")
    (d / "types.toml").write_text(
        DEFAULT_SCENARIO.read_text().replace("duration_s = 60.0", 'duration_s = "long"')
        .replace('"../ephemeris/', f'"{DEFAULT_SCENARIO.parent.parent}/ephemeris/'))
    (d / "motion_str.toml").write_text(
        DEFAULT_SCENARIO.read_text().split("[[motion]]")[0].replace(
            '"../ephemeris/', f'"{DEFAULT_SCENARIO.parent.parent}/ephemeris/')
        + 'motion = "circle"\n')
    (d / "emptydir").mkdir()
    (d / "study_typo.toml").write_text(
        '[study]\nname = "t"\nfilters = ["ekf", "ff-aukf"]\nruns = 1\n[[cells]]\n'
        'name = "baseline"\n[[cells]]\nname = "imu-typo"\n'
        'truth = { "imu.accel_random_walk_mps_sqrthz" = 0.5 }\n')
    _sigmf_pairs(d / "sigmf")
    for name, text in (("assume_grade", '[imu]\ngrade = "gimbal"\n'),
                       ("assume_neg_h", '[oscillator]\npreset = "tcxo"\nh0 = -2e-19\n'),
                       ("assume_key", "[initial_errors]\nheading_deg = 20\n"),
                       ("assume_osc", '[oscillator]\npreset = "ocxo"\n')):
        (d / f"{name}.toml").write_text(text)
    (d / "osc_preset.toml").write_text(
        DEFAULT_SCENARIO.read_text().replace(
            '"../ephemeris/', f'"{DEFAULT_SCENARIO.parent.parent}/ephemeris/')
        + '\n[oscillator]\npreset = "rubidium"\n')
    default_abs = DEFAULT_SCENARIO.read_text().replace(
        '"../ephemeris/', f'"{DEFAULT_SCENARIO.parent.parent}/ephemeris/')
    for name, old, new in (("imu_grade", 'grade = "mems"', 'grade = "gimbal"'),
                           ("imu_neg", "accel_bias_mg = 4.0", "accel_bias_mg = 4.0\n"
                                                              "gyro_misalignment_mrad = -1.0"),
                           ("atm_truth", "[receiver_clock]",
                            '[atmosphere]\ntruth = "nequick"\n\n[receiver_clock]'),
                           ("atm_neg", "[receiver_clock]",
                            '[atmosphere]\ntruth = "residuals"\nzwd_sigma_m = -0.05\n\n'
                            "[receiver_clock]")):
        assert old in default_abs
        (d / f"{name}.toml").write_text(default_abs.replace(old, new, 1))
    for name, table in (("jam_type", 'type = "pulse"\njs_db = 30.0\n'),
                        ("jam_bw", 'type = "noise"\njs_db = 30.0\nbandwidth_hz = -1.0e6\n'),
                        ("jam_js", 'type = "cw"\njs_db = 120.0\n'),
                        ("jam_band", ('type = "noise"\njs_db = 30.0\nbandwidth_hz = 2.0e6\n'
                                      'offset_hz = 1.2e6\n'))):
        (d / f"{name}.toml").write_text(DEFAULT_SCENARIO.read_text().replace(
            '"../ephemeris/', f'"{DEFAULT_SCENARIO.parent.parent}/ephemeris/')
            + "\n[[interference]]\n" + table)
    for folder, name, text in (("camp_corrupt", "campaign.json", '{"experiment": "x", '),
                               ("camp_list", "campaign.json", "[1, 2]"),
                               ("res_corrupt", "result.json", "\x00\x01"),
                               ("res_types", "result.json", '{"status": 5, "tables": 3}')):
        (d / folder).mkdir()
        (d / folder / name).write_text(text)


def _issue49_inputs(d: Path, generated: Path) -> None:
    """Inputs of issue 49's cases: a set beside its ephemeris and a scenario named like the
    outputs, a TOML nested 3000 deep, a million-cell study, text, constant and periodic
    bytes, a study spec with a plugin and a bad key."""
    import numpy as np

    shutil.copytree(generated, d / "navset")
    nav = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
    (d / "navset" / "s_nav.rnx").write_bytes(gzip.decompress(nav.read_bytes()))
    scenario = DEFAULT_SCENARIO.read_text().replace('"../ephemeris/',
                                                    f'"{REPO_ROOT}/ephemeris/')
    (d / "navset" / "x.json").write_text(scenario)
    (d / "navset" / "default_lc_ekf.csv").write_text(scenario)
    (d / "nested.toml").write_text("x = " + "[" * 3000 + "]" * 3000 + "\n")
    levels = ", ".join(str(float(v)) for v in range(1, 101))
    (d / "study_big.toml").write_text(
        '[study]\nname = "big"\nfilters = ["ekf"]\nruns = 1\n[factorial]\n'
        + "".join(f'"truth.imu.{k}" = [{levels}]\n'
                  for k in ("gyro_bias_deg_h", "accel_bias_mg", "gyro_scale_factor_ppm")))
    (d / "study_one.toml").write_text('[study]\nname = "one"\nfilters = ["ekf"]\nruns = 1\n')
    (d / "study_plugin.toml").write_text(
        '[study]\nname = "p"\nfilters = ["ekf", "no_such_module_i49:Filter"]\nruns = 0\n')
    (d / "text.bin").write_text(DEFAULT_SCENARIO.read_text() * 8)
    (d / "zeros.bin").write_bytes(bytes(200_000))
    rng = np.random.default_rng(1)
    (d / "pattern.bin").write_bytes(
        np.tile(rng.integers(-3, 4, 1000).astype(np.int8), 200).tobytes())


def _sigmf_pairs(d: Path) -> None:
    """SigMF pairs (metadata written as JSON here, 2000 bytes of data) that sdr-di refuses."""
    from sdr_di.constants import F_B3I

    d.mkdir()
    (d / "rec.sigmf").write_bytes(b"\x00" * 512)  # an archive (a tar file): not read
    for name, datatype, caps in (
            ("cu8", "cu8", [{"core:frequency": F_B3I}]),
            ("ci16_be", "ci16_be", [{"core:frequency": F_B3I}]),
            ("l1", "ci8", [{"core:frequency": 1575.42e6}]),
            ("off", "ci8", [{"core:frequency": F_B3I + 0.7e6}]),  # IF -0.7 MHz at 2.5 MHz
            ("two", "ci8", [{"core:frequency": F_B3I},
                            {"core:sample_start": 500, "core:frequency": F_B3I + 1e5}]),
            ("nofreq", "ci8", [{"core:datetime": "2020-01-01T00:00:00Z"}]),
            ("invalid", "ci8", [{"core:frequency": F_B3I}])):
        glob = {"core:datatype": datatype, "core:sample_rate": 2.5e6, "core:version": "1.2.0"}
        if name == "invalid":
            glob["core:sample_rate"] = "fast"
        caps = [{"core:sample_start": 0, **c} for c in caps]
        (d / f"{name}.sigmf-meta").write_text(json.dumps(
            {"global": glob, "captures": caps, "annotations": []}))
        (d / f"{name}.sigmf-data").write_bytes(bytes(range(250)) * 8)


def _snapshot(d: Path) -> set[str]:
    return {p.relative_to(d).as_posix() for p in d.rglob("*")}


@pytest.fixture(scope="module")
def workdir(if_files, tmp_path_factory) -> Path:
    """The work folder of the cases, made from the session's 0.02 s set (copied)."""
    d = tmp_path_factory.mktemp("bad_inputs")
    make_workdir(d, if_files(0.02, name="s").if_file.parent)
    return d


def run_case(argv: list[str], capsys) -> tuple[int, str, str]:
    """Run the CLI in-process; returns (exit status, stdout, stderr)."""
    try:
        rc = main(argv)
    except SystemExit as exc:  # only --help / --version may exit this way
        rc = exc.code if isinstance(exc.code, int) else 1
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


@pytest.mark.parametrize("argv,status", [(c[1], case_status(c)) for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2(workdir, capsys, argv, status):
    before = _snapshot(workdir)
    args = [a.format(d=workdir) for a in argv]
    rc, out, err = run_case(args, capsys)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert rc == status, (rc, err)
    assert len(lines) == 1 and lines[0].startswith("sdr-di: error: "), err
    assert _snapshot(workdir) == before, sorted(_snapshot(workdir) - before)


def test_no_command_prints_one_line_and_help_still_works(capsys):
    rc, out, err = run_case([], capsys)
    assert rc == 2 and err.strip() == ("sdr-di: error: the following arguments are required: "
                                       "command (see sdr-di --help)")
    rc, out, err = run_case(["run", "--help"], capsys)
    assert rc == 0 and out.startswith("usage: sdr-di run") and err == ""


# -- report on a campaign with an unreadable run record -----------------------------------------

def test_report_warns_for_each_unreadable_run_record(tmp_path, capsys):
    d = tmp_path / "campaign"
    (d / "runs").mkdir(parents=True)
    (d / "campaign.json").write_text(json.dumps({
        "experiment": EXP, "status": "interrupted", "runs": 3, "tables": [], "params": {}}))
    (d / "runs" / "0.json").write_text(json.dumps(
        {"index": 0, "seed": 1, "status": "ok", "figures": {"pos_m_rmse": 1.5}}))
    (d / "runs" / "1.json").write_text('{"index": 1, "seed": 2, "stat')  # killed mid-write
    (d / "runs" / "2.json").write_text("[]")
    rc, out, err = run_case(["report", str(d)], capsys)
    assert rc == 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 2 and all(ln.startswith("sdr-di: warning: run record ") for ln in lines)
    assert "1.json" in lines[0] and "2.json" in lines[1]
    html = (d / "report.html").read_text()
    assert "could not be read: 1.json, 2.json" in html and "1 of 3 runs completed" in html


# -- Ctrl-C at three points: during an import, during generation, during a campaign -------------

_INTERRUPT_AT_IMPORT = """
import os, signal, sys
from importlib.abc import MetaPathFinder
# a terminal's Ctrl-C: whatever disposition the test process left to its children
signal.signal(signal.SIGINT, signal.default_int_handler)

class Interrupt(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "numba":  # first imported inside main(), by the generate command
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, Interrupt())
from sdr_di.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_during_import_is_one_line(tmp_path):
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-c", _INTERRUPT_AT_IMPORT, *GD, "--out",
                          str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 130 and res.stderr == "sdr-di: interrupted\n", res.stderr
    assert not (tmp_path / "o").exists()


# (during generation: tests/test_output_sets.py::test_killed_regeneration_keeps_the_earlier_set)


def test_ctrl_c_during_a_campaign_is_one_line_without_dask_noise(tmp_path):
    """SIGINT to the whole process group, as a terminal's Ctrl-C: the workers must not print
    their own tracebacks, the scheduler no error log."""
    import os
    import signal
    import subprocess
    import sys

    out = tmp_path / "c"
    # the worker killed mid-run cannot remove its run's temporary folder (sdr-di-run-*) or
    # Dask's scratch space: they go under tmp_path, not into the system's temp folder
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen(
        [sys.executable, "-m", "sdr_di.cli", "campaign", EXP, "--runs", "40", "--workers", "1",
         "--duration", "5", "--out", str(out), "--no-report"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env={**os.environ, "TMPDIR": str(tmp)})
    first = proc.stdout.readline()  # the first finished run: workers are busy now
    assert first.strip().startswith("run"), (first, proc.stderr.read() if not first else "")
    os.killpg(proc.pid, signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (rest, err)
    assert err == "sdr-di: interrupted\n", err
    assert json.loads((out / "campaign.json").read_text())["status"] == "interrupted"
