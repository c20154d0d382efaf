#!/usr/bin/env python3
"""Traces the latency benchmark's tails to their cause.

The latency example lists every timed state above 1 ms end to end with its publish time
(CLOCK_MONOTONIC) and each run's span. Run it under a system-wide trace on the same clock, then
give both to this script:

    perf record -k CLOCK_MONOTONIC -a -m 16M -o trace.data -e sched:sched_switch,sched:sched_waking,\
irq_vectors:reschedule_entry,irq_vectors:call_function_single_entry,\
irq_vectors:local_timer_entry,workqueue:workqueue_execute_start,workqueue:workqueue_execute_end \
        -- target/release/examples/latency --seconds 5 > run.md
    python3 tools/replay/examples/latency_tails.py run.md trace.data

For each listed state it takes the slowest hop and the process that hop waited for (calibrate,
odometry or the benchmark's subscriber), then follows that process's wake-up: the last
`sched_waking` of it (time w, target CPU c) before it was switched in (time s), and the first
wake-up interrupt (reschedule or call-function IPI) CPU c took after w (time i). Each wait is put
in the first class that fits:
- idle, untraced exit: no switch to the process after w is recorded (on this VM the trace
  misses the switches out of idle on one CPU); the CPU's first event after w bounds when it
  ran: more than 0.5 ms after w, its idle vCPU took nothing for that long;
- on its CPU: the process was woken and switched in in time but took the sample more than
  0.5 ms later (its own work first, or it was switched out again; said apart when its CPU took
  no interrupt for more than a tick period meanwhile);
- sender held up: w came more than 0.5 ms after the hop began (and, where the sender's CPU
  took no interrupt for more than a tick period meanwhile, that is said);
- no interrupt: CPU c, busy, took no interrupt at all for more than one 250 Hz tick period
  (4.5 ms) within w..s, or (for a SCHED_FIFO receiver, which is always sent an IPI) its IPI came
  more than 0.5 ms after w: the vCPU was not running (the hypervisor ran something else) or
  had interrupts off;
- idle: CPU c was idle; its wake-up interrupt came more than 0.5 ms after w (the host had not
  been running the halted vCPU), or other;
- queued: another of the run's processes ran longest on CPU c in w..s;
- not preempted (SCHED_FIFO receivers): the IPI came in time but the task that ran longest on
  CPU c kept it for more than 0.5 ms: kernel code that does not reschedule (a PREEMPT_NONE kernel preempts only on
  return to user space or at explicit rescheduling points);
- CFS (SCHED_OTHER receivers): the fair scheduler ran another task first (the longest named);
- other.
Each class is printed with its count and the median and longest wait. Kernel workqueue items
longer than 0.3 ms that overlap a wait are named with it. A wait near events perf lost (a
PERF_RECORD_LOST on its CPUs within 1 s after it) is not classified. Last, our processes' on-CPU slices
above 1 ms while the run's live states arrived, split by whether their CPU took an interrupt
within a tick period (work, or kernel work in the process) or not (the vCPU did not run).
perf's `script` output is parsed here: no Python package reads perf.data.
"""
import bisect
import collections
import re
import subprocess
import sys

# The process each hop waits for: replay -> calibrate, calibrate -> odometry, odometry -> us.
RECEIVERS = ["calibrate", "odometry", "subscriber"]
LATE_NS = 500_000
# Longer than this with no event at all on a busy CPU is more than one 250 Hz tick period.
NO_TICK_NS = 4_500_000
LONG_WORK_NS = 300_000
IPIS = ("irq_vectors:reschedule_entry", "irq_vectors:call_function_single_entry")


def runs_of(md):
    """[(title, [first, last] ns, {name: pid}, [(published ns, [hop us x4])])] from the
    benchmark's markdown output."""
    runs, cur = [], None
    with open(md) as f:
        for line in f:
            if line.startswith("## "):
                cur = (line[3:].strip(), [], {}, [])
                runs.append(cur)
            m = re.search(r"arrived from CLOCK_MONOTONIC (\d+) to (\d+) ns", line)
            if m and cur:
                cur[1].extend(int(x) for x in m.groups())
                pids = re.search(r"\(pids: ([^)]*)\)", line).group(1)
                for name, pid in re.findall(r"(\w+) (\d+)", pids):
                    cur[2][name] = int(pid)
            m = re.match(r"\| (\d{9,}) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \|", line)
            if m and cur:
                cur[3].append((int(m.group(1)), [float(x) for x in m.groups()[1:]]))
    return [r for r in runs if r[1]]


class Trace:
    """The events of one perf.data, indexed per CPU."""

    def __init__(self, out):
        """Indexes `perf script -F cpu,time,event,trace --ns --show-lost-events` output."""
        line_re = re.compile(r"\s*\[(\d+)\]\s+([\d.]+):\s+(\S+?):?(?:\s+(.*))?$")
        self.lost = collections.defaultdict(list)  # cpu -> times of PERF_RECORD_LOST
        self.any = collections.defaultdict(list)  # cpu -> event times
        self.ipi = collections.defaultdict(list)  # cpu -> IPI entry times
        self.switch = collections.defaultdict(list)  # cpu -> (time, next comm, next pid)
        self.switch_in = collections.defaultdict(list)  # pid -> times it was switched in
        self.waking = collections.defaultdict(list)  # pid -> (time, prio, target cpu, waker cpu)
        self.work = []  # (start, end, function, cpu) of long workqueue items
        started = {}
        for line in out.splitlines():
            m = line_re.match(line)
            if not m:
                continue
            cpu, t, event, rest = int(m.group(1)), round(float(m.group(2)) * 1e9), m.group(3), m.group(4) or ""
            if event == "PERF_RECORD_LOST":
                self.lost[cpu].append(t)
                continue
            self.any[cpu].append(t)
            if event == "sched:sched_switch":
                n = re.search(r"==> next_comm=(.*?) next_pid=(\d+)", rest)
                self.switch[cpu].append((t, n.group(1), int(n.group(2))))
                self.switch_in[int(n.group(2))].append(t)
            elif event == "sched:sched_waking":
                w = re.search(r"pid=(\d+) prio=(\d+) target_cpu=(\d+)", rest)
                self.waking[int(w.group(1))].append((t, int(w.group(2)), int(w.group(3)), cpu))
            elif event in IPIS:
                self.ipi[cpu].append(t)
            elif event.startswith("workqueue:workqueue_execute_"):
                k = re.search(r"work struct (0x[0-9a-f]+)(?:: function (\S+))?", rest)
                if event.endswith("start"):
                    started[(cpu, k.group(1))] = (t, k.group(2))
                elif (cpu, k.group(1)) in started:
                    t0, fn = started.pop((cpu, k.group(1)))
                    # Writeback items sleep on I/O for seconds: their span is not CPU held.
                    if t - t0 > LONG_WORK_NS and fn != "wb_workfn":
                        self.work.append((t0, t, fn, cpu))
        for d in (self.any, self.ipi, self.switch, self.switch_in, self.waking, self.lost):
            for v in d.values():
                v.sort()

    def occupant(self, cpu, t0, t1, but):
        """(comm, pid) that ran longest on `cpu` in [t0, t1], other than pid `but`."""
        s = self.switch[cpu]
        k = max(0, bisect.bisect_right(s, (t0, "\uffff", 1 << 62)) - 1)
        ran = collections.Counter()
        for i in range(k, len(s)):
            a, comm, pid = s[i]
            if a >= t1:
                break
            b = s[i + 1][0] if i + 1 < len(s) else t1
            if pid != but:
                ran[(comm, pid)] += min(b, t1) - max(a, t0)
        return ran.most_common(1)[0][0] if ran else ("?", -1)

    def lossy(self, cpu, t0, t1):
        """Whether perf lost events of `cpu` around [t0, t1] (its record comes after them)."""
        return self.first(self.lost[cpu], t0, t1 + 1_000_000_000) is not None

    def silence(self, cpu, t0, t1):
        """The longest interval in [t0, t1] with no event on `cpu`, ns."""
        a = self.any[cpu]
        pts = [t0] + a[bisect.bisect_left(a, t0):bisect.bisect_right(a, t1)] + [t1]
        return max(b - a for a, b in zip(pts, pts[1:]))

    def first(self, times, t0, t1):
        k = bisect.bisect_left(times, t0)
        return times[k] if k < len(times) and times[k] <= t1 else None


def task(comm):
    """A task's name without its instance number (`opt cgu.07` -> `opt cgu.`)."""
    return re.sub(r"[/:]?\d+.*$", "", comm) or comm


def classify(tr, pids, published, hops):
    """(class, wait ns) of the slowest hop of a state published at `published`; `pids` names
    the run's processes."""
    k = max(range(3), key=lambda i: hops[i])
    t0 = published + round(sum(hops[:k]) * 1000)
    t1 = t0 + round(hops[k] * 1000)
    work = sorted({fn for a, b, fn, c in tr.work if a < t1 and b > t0})
    note = f" [kernel work: {', '.join(work)}]" if work else ""
    receiver = RECEIVERS[k]
    pid = pids[receiver]
    ours = {p: n for n, p in pids.items()}
    # The switch-in after which the receiver took the sample (it stamps it on receipt), and
    # the wake-up that made it runnable.
    ins = tr.switch_in[pid]
    s = ins[max(0, bisect.bisect_right(ins, t1 + 50_000) - 1)]
    wakes = tr.waking[pid]
    j = bisect.bisect_right(wakes, (s,)) - 1
    if j < 0:
        return f"{receiver}: no wake-up in the trace{note}", t1 - t0
    latest = bisect.bisect_right(wakes, (t1,)) - 1
    if latest > j:
        j = latest
    w, prio, cpu, waker_cpu = wakes[j]
    rt = prio < 100
    if tr.lossy(cpu, t0, t1) or tr.lossy(waker_cpu, t0, t1):
        return f"{receiver}: not known, the trace lost events{note}", t1 - t0
    if s < w:
        # No switch-in after the wake-up in the trace: on this VM the switches out of idle on
        # some CPUs are not recorded. The CPU's first event after w bounds when it ran.
        first = tr.first(tr.any[cpu], w + 1, t1 + 1_000_000) or t1
        if first - w > LATE_NS:
            return f"{receiver}: its idle vCPU took nothing for a while after the wake-up{note}", first - w
        return f"{receiver}: woken on its idle CPU in time, the rest after it{note}", t1 - first
    if t1 - max(s, t0) > LATE_NS and s - w <= LATE_NS:
        # Woken in time; the time went after it was switched in.
        if tr.silence(cpu, max(s, t0), t1) > NO_TICK_NS:
            return f"{receiver}: on its CPU, which took no interrupt{note}", t1 - max(s, t0)
        return f"{receiver}: on its CPU before it took the sample{note}", t1 - max(s, t0)
    if w - t0 > LATE_NS:
        if tr.silence(waker_cpu, t0, w) > NO_TICK_NS:
            return f"{receiver}: sender held up, its vCPU took no interrupt{note}", w - t0
        return f"{receiver}: sender held up{note}", w - t0
    comm, cur_pid = tr.occupant(cpu, w, s, pid)
    ipi = tr.first(tr.ipi[cpu], w, s + 1_000_000)
    if cur_pid == 0:
        if ipi is None or ipi - w > LATE_NS:
            return f"{receiver}: its idle vCPU took the wake-up interrupt late{note}", s - w
        return f"{receiver}: its CPU was idle, other{note}", s - w
    if tr.silence(cpu, w, s) > NO_TICK_NS or (rt and (ipi is None or ipi - w > LATE_NS)):
        return f"{receiver}: its vCPU took no interrupt{note}", s - w
    if cur_pid in ours:
        return f"{receiver}: queued behind {ours[cur_pid]} on its CPU{note}", s - w
    if rt and s - ipi > LATE_NS:
        return f"{receiver}: not preempted, {task(comm)} in the kernel{note}", s - w
    if not rt:
        return f"{receiver}: CFS ran {task(comm)} first{note}", s - w
    return f"{receiver}: other{note}", s - w


def perf_script(data):
    """The events of a perf.data file as `Trace` reads them."""
    return subprocess.run(
        ["perf", "script", "-i", data, "-F", "cpu,time,event,trace", "--ns", "--show-lost-events"],
        capture_output=True, text=True, check=True,
    ).stdout


def report(runs, tr):
    """Prints the classes of each run's tails and our long on-CPU slices."""
    for title, (w0, w1), pids, tails in runs:
        waits = collections.defaultdict(list)
        for t, h in tails:
            label, ns = classify(tr, pids, t, h)
            waits[label].append(ns / 1e6)
        print(f"{title}: {len(tails)} listed states above 1 ms")
        print("  count  median ms  max ms  slowest hop's receiver: cause")
        for label, v in sorted(waits.items(), key=lambda kv: -len(kv[1])):
            v.sort()
            print(f"  {len(v):5d}  {v[len(v) // 2]:9.2f}  {v[-1]:6.2f}  {label}")
        slices = collections.defaultdict(list)
        ours = {p: n for n, p in pids.items()}
        for cpu, sw in tr.switch.items():
            for (a, _, pid), (b, _, _) in zip(sw, sw[1:]):
                if w0 <= a <= w1 and pid in ours and b - a > 1_000_000 and not tr.lossy(cpu, a, b):
                    ran = tr.silence(cpu, a, b) <= NO_TICK_NS
                    slices[(ours[pid], "interrupts taken" if ran else "no interrupt")].append((b - a) / 1e6)
        print("  our on-CPU slices above 1 ms: count  median ms  max ms  process: its CPU")
        for (comm, how), v in sorted(slices.items()):
            v.sort()
            print(f"  {len(v):5d}  {v[len(v) // 2]:9.2f}  {v[-1]:6.2f}  {comm}: {how}")


def self_test():
    """Each class on a hand-made trace of one hop (replay pid 10 on CPU 0 -> calibrate pid 11,
    subscriber pid 13): times in us from 1 s."""

    def ev(cpu, us, what):
        return f"[{cpu:03d}] {1 + us * 1e-6:.9f}: {what}"

    def switch(cpu, us, prev, prev_pid, nxt, pid):
        return ev(cpu, us, f"sched:sched_switch: prev_comm={prev} prev_pid={prev_pid} "
                  f"prev_prio=120 prev_state=S ==> next_comm={nxt} next_pid={pid} next_prio=49")

    def waking(cpu, us, pid, prio, target):
        return ev(cpu, us, f"sched:sched_waking: comm=x pid={pid} prio={prio} target_cpu={target:03d}")

    ipi = "irq_vectors:reschedule_entry: vector=253"
    tick = "irq_vectors:local_timer_entry: vector=236"
    pids = {"replay": 10, "calibrate": 11, "odometry": 12, "subscriber": 13}
    # The sample is published at 1000 us; calibrate stamps it on receipt, 2000 us later.
    hops = [2000.0, 10.0, 10.0, 2020.0]
    cases = {
        # The IPI comes at once, the linker keeps CPU 1 for 2 ms (kernel code).
        "not preempted, ld in the kernel": [
            switch(1, 0, "swapper/1", 0, "ld", 50), waking(0, 1005, 11, 49, 1),
            ev(1, 1010, ipi), ev(1, 2000, tick), switch(1, 3000, "ld", 50, "mems-calibrate", 11)],
        # CPU 1 takes nothing for 2 ms: its IPI comes with the switch.
        "its vCPU took no interrupt": [
            switch(1, 0, "swapper/1", 0, "ld", 50), waking(0, 1005, 11, 49, 1),
            ev(1, 2990, ipi), switch(1, 3000, "ld", 50, "mems-calibrate", 11)],
        # A SCHED_OTHER calibrate waits for CFS to finish the compiler's turn.
        "CFS ran rustc first": [
            switch(1, 0, "swapper/1", 0, "rustc", 50), waking(0, 1005, 11, 120, 1),
            ev(1, 2000, tick), switch(1, 3000, "rustc", 50, "mems-calibrate", 11)],
        # The replay wakes calibrate 1.9 ms after stamping the sample.
        "sender held up": [
            switch(1, 0, "swapper/1", 0, "mems-calibrate", 11), ev(0, 1500, tick),
            waking(0, 2900, 11, 49, 1), ev(1, 2905, ipi),
            switch(1, 2910, "swapper/1", 0, "mems-calibrate", 11)],
    }
    for want, lines in cases.items():
        tr = Trace("\n".join(lines))
        label, _ = classify(tr, pids, 1_001_000_000, hops)
        assert label == f"calibrate: {want}", (want, label)
    md = ("## Pipeline\n\nLive states arrived from CLOCK_MONOTONIC 1 to 2 ns (pids: replay 10, "
          "calibrate 11, odometry 12, subscriber 13). CPU ...\n\n| 1001000000 | 2000.0 | 10.0 | 10.0 "
          "| 2020.0 |\n")
    import tempfile
    with tempfile.NamedTemporaryFile("w", suffix=".md") as f:
        f.write(md)
        f.flush()
        assert runs_of(f.name) == [("Pipeline", [1, 2], pids, [(1001000000, hops)])]
    print("latency_tails self-test: ok")


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    if len(sys.argv) != 3:
        sys.exit("usage: latency_tails.py RUN.md TRACE.data | --self-test")
    report(runs_of(sys.argv[1]), Trace(perf_script(sys.argv[2])))


if __name__ == "__main__":
    main()
