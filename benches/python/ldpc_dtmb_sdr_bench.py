"""dtmb-sdr's CPU LDPC decoder on the LLRs of hybridnav's criterion bench
`dtmb_data_layer/ldpc_decode_codeword_r0.6`.

dtmb-sdr (PyPI `dtmb-sdr`, MIT) ships its LDPC + BCH stage as the program
`dtmb/bin/dtmb_core_ldpc_bch_decode`, which `dtmb-decode` runs as the last stage of its
pipeline. It reads little-endian f32 LLRs (positive for 0) of whole signal frames
(`--codewords-per-frame` codewords of 7488 transmitted bits) and writes TS bytes; on exit
it prints counters to stderr, among them `codewords`, `converged_codewords`,
`ldpc_iterations` and `batch_worker_ms`, the wall time of its decoding workers (flooding
normalised min-sum, `ldpc_decode_min_sum_sparse`, plus BCH and descrambling of each
codeword).

Usage (after `HYBRIDNAV_LDPC_LLR_OUT=/tmp/llr.f32 cargo bench --bench dtmb --
ldpc_decode`, which writes the bench's codeword):

    python3 benches/python/ldpc_dtmb_sdr_bench.py /tmp/llr.f32 [frames] [runs]

The codeword is repeated 3 times per frame (64QAM 0.6) for `frames` frames; the decoder
runs on one worker (one core) with 50 iterations at most, as hybridnav's decoder, and
its pipeline's attenuation 0.65. Reported: codewords per second from `batch_worker_ms`
(decoding only) and from the process's wall time (including start-up and file I/O), best
and median of `runs`.
"""

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import dtmb  # the installed dtmb-sdr package

CODEWORD_BITS = 7488
CODEWORDS_PER_FRAME = 3  # 64QAM with the rate-0.6 code


def main() -> None:
    llr_path = Path(sys.argv[1])
    frames = int(sys.argv[2]) if len(sys.argv) > 2 else 200
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    one = llr_path.read_bytes()
    if len(one) != 4 * CODEWORD_BITS:
        sys.exit(f"{llr_path}: expected {4 * CODEWORD_BITS} bytes (7488 f32), got {len(one)}")
    package = Path(dtmb.__file__).parent
    exe = package / "bin" / "dtmb_core_ldpc_bch_decode"
    alist = package / "data" / "dtmb_ldpc_rate2.alist"
    with tempfile.TemporaryDirectory() as tmp:
        llr_file = Path(tmp) / "frames.llr.f32"
        llr_file.write_bytes(one * (frames * CODEWORDS_PER_FRAME))
        out = Path(tmp) / "out.ts"
        worker_rates, wall_rates = [], []
        for _ in range(runs):
            cmd = [
                str(exe),
                "--fec-rate", "2",
                "--alist", str(alist),
                "--codewords-per-frame", str(CODEWORDS_PER_FRAME),
                "--workers", "1",
                "--ldpc-accel", "cpu",
                "--max-iterations", "50",
                "--retry-max-iterations", "50",
                "--attenuation", "0.65",
                str(llr_file),
                str(out),
            ]
            t0 = time.perf_counter()
            p = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if p.returncode != 0:
                sys.exit(f"dtmb_core_ldpc_bch_decode failed ({p.returncode}):\n{p.stderr}")
            stats = dict(
                line.split("=", 1) for line in p.stderr.splitlines() if "=" in line
            )
            n = int(stats["codewords"])
            worker_rates.append(n / (float(stats["batch_worker_ms"]) * 1e-3))
            wall_rates.append(n / wall)
        print(
            f"dtmb-sdr {dtmb.__version__ if hasattr(dtmb, '__version__') else ''} "
            f"CPU LDPC decoder, 1 worker, {n} codewords (rate 0.6): "
            f"converged {stats['converged_codewords']}, "
            f"{int(stats['ldpc_iterations']) / n:.2f} iterations per codeword; "
            f"decoding {max(worker_rates):.0f} codewords/s best, "
            f"{statistics.median(worker_rates):.0f} median "
            f"({1e3 / max(worker_rates):.3f} ms per codeword best); "
            f"whole process {max(wall_rates):.0f} codewords/s best, "
            f"{statistics.median(wall_rates):.0f} median"
        )
        print("load average", os.getloadavg())


if __name__ == "__main__":
    main()
