"""Sections of docs/acquisition.md: the driver and the stack as real processes, and the
acquisition loop's bench. Every live run has a namespace of its own, so that other iceoryx2
users of the machine neither see nor disturb it."""

import re

from common import Failed, Section, table

B = "target/release/"


def verbatim(text):
    """Command output as an indented block."""
    return "\n".join("    " + l for l in text.strip().splitlines())


def topic_and_acquire(ctx, ns, acquire_args, seconds):
    """`mems-topic hz --json` on the raw service while `mems-acquire` publishes for `seconds`."""
    script = f"""
{B}mems-topic hz mems/imu/raw --namespace {ns} --duration {seconds + 2.5} --json > /tmp/{ns}-topic.json &
topic=$!
sleep 0.5
{B}mems-acquire --namespace {ns} {acquire_args} --duration {seconds}
wait $topic
cat /tmp/{ns}-topic.json
rm -f /tmp/{ns}-topic.json
"""
    out, err = ctx.shell(script)
    return out, err


def clock(ctx):
    """The internal oscillator 8 % slow and 8 % fast, at 1 kHz over the simulated I2C part."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "acquire", "-p", "mems-topic"])
    seconds = 3 if ctx.quick else 10
    blocks = []
    for ppm in (-80000, 80000):
        out, err = topic_and_acquire(ctx, f"figures-clock{ppm}", f"--source sim --rate 1000 --sim-clock-ppm {ppm}", seconds)
        summary = [l for l in err.splitlines() if "published" in l or "FIFO" in l or "gaps" in l]
        blocks.append(f"`--sim-clock-ppm {ppm}`:\n\n" + verbatim("\n".join(summary[-3:]) + "\n" + out))
    return {"acquisition-clock": "\n\n".join(blocks)}


def spi(ctx):
    """4 kHz over the simulated SPI part through iceoryx2, and the refusal of 4 kHz on I2C."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "acquire", "-p", "mems-topic"])
    ctx.region = "acquisition-spi"
    out, err = topic_and_acquire(ctx, "figures-spi", "--source sim-spi --rate 4000", 3 if ctx.quick else 10)
    summary = [l for l in err.splitlines() if "published" in l or "FIFO" in l or "lateness" in l or "gaps" in l]
    ctx.region = "acquisition-i2c-refusal"
    refused, _ = ctx.shell(f"{B}mems-acquire --namespace figures-i2c --source sim --rate 4000 --duration 1 2>&1 && exit 1 || true")
    return {
        "acquisition-spi": verbatim("\n".join(summary[-4:]) + "\n" + out),
        "acquisition-i2c-refusal": verbatim(refused),
    }


def soak(ctx):
    """The full stack at 4 kHz over simulated SPI for 10 minutes, recorded, then reported."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-stack", "-p", "mems-record", "-p", "acquire", "-p", "calibrate",
             "-p", "calibrate-science", "-p", "odometry", "-p", "mems-sim"])
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-record", "--example", "recording_report"])
    duration = 20 if ctx.quick else 600
    out, err = ctx.shell(f"""
MEMS_NAMESPACE=figures-soak {B}mems-stack --source sim-spi --rate 4000 --duration {duration} --record /tmp/figures-soak.mcap --force > /dev/null
{B}examples/recording_report /tmp/figures-soak.mcap
rm -f /tmp/figures-soak*.mcap
""")
    return {"acquisition-soak": verbatim(out)}


LOOP = re.compile(
    r"^\s*(?P<rate>\d+) Hz over (?P<bus>.+?), read every (?P<every>[0-9.]+) ms: (?P<rate_s>[0-9.]+) samples/s "
    r"sustained over \d+ s, bus utilisation (?P<util>[0-9.]+) %, host CPU (?P<cpu>[0-9.]+) us/sample, "
    r"lost (?P<lost>\d+), overflows (?P<over>\d+), reads \d+$",
    re.M,
)


def loop_bench(ctx):
    """The acquisition loop on a virtual clock under the bus models (`acquire_loop` bench)."""
    out, _ = ctx.run(["cargo", "bench", "-q", "-p", "acquire", "--bench", "acquire_loop"])
    if ctx.dry:
        return {}
    rows = [
        [f"{m['rate']} Hz over {m['bus']}, read every {m['every']} ms", f"{m['rate_s']} samples/s", f"{m['util']} %",
         f"{m['cpu']} us", m["lost"], m["over"]]
        for m in LOOP.finditer(out)
    ]
    if not rows:
        raise Failed("acquire_loop: no result line")
    header = ["configuration", "sustained", "bus utilisation", "host CPU / sample", "lost", "overflows"]
    return {"acquisition-loop": table(header, rows)}


def kills(ctx):
    """A recorder killed in a stack run (the run's two files read as one), and a killed stack's
    children and work directory."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-stack", "-p", "mems-record", "-p", "acquire", "-p", "calibrate",
             "-p", "calibrate-science", "-p", "odometry", "-p", "mems-sim"])
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-record", "--example", "recording_report"])
    ctx.region = "acquisition-recorder-kill"
    rec, _ = ctx.shell(f"""
rm -f /tmp/figures-kill.mcap /tmp/figures-kill.*.mcap
{B}mems-stack --duration {20 if ctx.quick else 60} --record /tmp/figures-kill.mcap --namespace figures-killrec > /dev/null 2>&1 &
stack=$!; sleep {8 if ctx.quick else 20}
for k in $(cat /proc/$stack/task/$stack/children); do [ "$(cat /proc/$k/comm)" = mems-record ] && kill -KILL $k; done
wait $stack
{B}examples/recording_report /tmp/figures-kill.mcap
rm -f /tmp/figures-kill.mcap /tmp/figures-kill.*.mcap
""")
    ctx.region = "acquisition-stack-kill"
    stack, _ = ctx.shell(f"""
{B}mems-stack --namespace figures-killstack > /dev/null 2>&1 &
stack=$!; sleep 10; kids=$(cat /proc/$stack/task/$stack/children)
kill -KILL $stack; t0=$(date +%s%N)
alive() {{ for k in $kids; do s=$(awk '{{print $3}}' /proc/$k/stat 2>/dev/null) && [ "$s" != Z ] && return 0; done; return 1; }}
while alive; do sleep 0.002; done; echo "children gone $(( ($(date +%s%N) - t0) / 1000000 )) ms after the kill"
{B}mems-stack --namespace figures-killstack --duration 1 2>&1 | grep removed || true
""")
    return {"acquisition-recorder-kill": verbatim(rec), "acquisition-stack-kill": verbatim(stack)}


SECTIONS = [
    Section("acquisition-clock", "acquisition.md", ["acquisition-clock"], "1 min", clock),
    Section("acquisition-spi", "acquisition.md", ["acquisition-spi", "acquisition-i2c-refusal"], "1 min", spi),
    Section("acquisition-soak", "acquisition.md", ["acquisition-soak"], "11 min", soak),
    Section("acquisition-loop", "acquisition.md", ["acquisition-loop"], "2 min", loop_bench),
    Section("acquisition-kills", "acquisition.md", ["acquisition-recorder-kill", "acquisition-stack-kill"], "2 min", kills),
]
