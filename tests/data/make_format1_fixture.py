"""How tests/data/format1-recording.mcap was made: with the FORMAT-1 recorder, i.e. this script run from a copy of
hamr-bench at commit c49d3cfa301fa025a1eced8bc276ae0c1473e2c9 (`git archive c49d3cf | tar -x -C OLD; cd OLD;
python3 make_format1_fixture.py OUT.mcap`), not from the code under test. The file is the old writer's output,
kept so that reading old recordings stays tested (tests/recording/test_format1_fixture.py rebuilds the values
written here and compares). Every kind of message a run writes, small: scalars at 1 kHz and 50 Hz, events with a
step condition, raw frames in stored chunks (which in format 1 interleave with the scalar chunks out of log-time
order), the tracked displacement, serial traffic."""
import sys
import numpy as np
from hamr_bench.recording import Recorder

out = sys.argv[1]
rng = np.random.default_rng(7)
rec = Recorder(out, overwrite=True, start_time_ns=1_795_000_000_000_000_000)
rec.add_metadata("rig", {"name": "fixture", "path": "", "text": "", "kind": "sim"})
rec.add_metadata("protocol", {"name": "free-displacement", "params": "{}", "protocol_file": ""})
rec.write_event(0.0, "run_start", 0, "protocol free-displacement")
rec.write_event(0.01, "step", 0, "100 V", voltage_V=100.0, repetition=0, direction="up")
for i in range(400):
    t = i * 1e-3
    rec.write_scalar("/force", t, force_N=1e-3 * np.sin(i / 20))
    if i % 20 == 0:
        rec.write_scalar("/stage/position", t, position_m=1e-3)
        rec.write_scalar("/amplifier/drive/monitor", t, voltage_V=float(i) / 4)
    rec.write_scalar("/amplifier/drive/command", t, voltage_V=float(i) / 4)
    if i % 50 == 0:
        frame = rng.integers(0, 4, size=(24, 32), dtype=np.uint8)
        frame[10:14, 14 + i // 100:18 + i // 100] = 200
        rec.write_image("/camera/image", t, frame)
        rec.write_scalar("/camera/displacement", t, displacement_m=1e-6 * i, x_px=16.0 + i / 100, y_px=12.0)
rec.write_bytes("/traffic/stage", 0.2, "tx", b"1TP?\r\n")
rec.write_bytes("/traffic/stage", 0.21, "rx", b"1TP0.001\r\n")
rec.write_event(0.39, "safe_state", 0, "0 V commanded, stage stopped")
rec.write_event(0.4, "run_end", 0, "completed", exit_status="success")
rec.close("success", "completed")
