"""JFR execution samples of in-process ``Engine.fire`` (the reception set, 5 facts) in the tree on
PYTHONPATH: each method's inclusive share of the samples inside ``Runner.fire``, and for the methods
named, what they call (issue 27: where a fire's JVM time goes, tree against tree).

    cd <tree> && PYTHONPATH=$PWD .venv/bin/python <this>/bench/fire_jfr.py 20 Runner.giveBack,Runner.buildFacts
"""
import collections, json, sys, tempfile, time
from gateway.config import Settings
from gateway.engine import Engine
sys.path.insert(0, 'bench'); import http_bench as hb
facts = hb.teahouse_facts()
tmp = tempfile.mkdtemp()
s = Settings.model_validate({'data_dir': tmp + '/d', 'engine': {'rules_dir': 'rules/drl'}})
e = Engine(s); e.seed(s.engine.rules_dir) if hasattr(e, 'seed') else e.seed_from()
secs = float(sys.argv[1]) if len(sys.argv) > 1 else 20
end = time.perf_counter() + 10
while time.perf_counter() < end: e.fire('reception', facts)
import jpype
Recording = jpype.JClass('jdk.jfr.Recording'); Duration = jpype.JClass('java.time.Duration')
rec = Recording(); rec.enable('jdk.ExecutionSample').withPeriod(Duration.ofMillis(1)); rec.start()
n = 0; t0 = time.thread_time(); end = time.perf_counter() + secs
while time.perf_counter() < end: e.fire('reception', facts); n += 1
cpu = time.thread_time() - t0
rec.stop(); path = tmp + '/r.jfr'; rec.dump(jpype.JClass('java.nio.file.Path').of(path))
keys = sys.argv[2].split(',') if len(sys.argv) > 2 else []
RF = jpype.JClass('jdk.jfr.consumer.RecordingFile')
under = collections.Counter(); incl = collections.Counter(); top = collections.Counter(); total = 0
for ev in RF.readAllEvents(jpype.JClass('java.nio.file.Path').of(path)):
    st = ev.getStackTrace()
    if st is None: continue
    frames = [str(f.getMethod().getType().getName()).split(".")[-1] + "." + str(f.getMethod().getName()) for f in st.getFrames()]
    if not any('Runner.fire' == x for x in frames): continue
    total += 1
    top[frames[0]] += 1
    for m in set(frames): incl[m] += 1
    for focus in keys:
        if focus in frames:
            i = frames.index(focus)
            under[(focus, frames[i-1] if i > 0 else '(self)')] += 1
print('fires', n, 'cpu_us/fire', round(cpu / n * 1e6, 1), 'samples in Runner.fire', total)
for k in keys:
    print(f'  {k}: {incl[k] / max(total,1):.3f}')
for (f, c), k in sorted(under.items(), key=lambda x: -x[1]): print(f'    {f} -> {c}: {k/total:.3f}')
print('top inclusive:')
for m, c in incl.most_common(45): print(f'  {c/total:.3f} {m}')
print('top self:')
for m, c in top.most_common(20): print(f'  {c/total:.3f} {m}')
