"""REST recorded fire at N connections against the tree given: CPU per request of the server's
process tree (the embedded database included), split by thread (the loop = each process's main
thread; JVM threads by name), over the measured window only (issue 25: where the server spends a
request, tree against tree; CPU per request is disturbed less by a busy machine than req/s).

    .venv/bin/python bench/rest_threads.py TREE [seconds] [conns]
"""
import asyncio, collections, json, os, sys, tempfile, time
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))
import http_bench as hb
tree = Path(sys.argv[1]).resolve()
secs = float(sys.argv[2]) if len(sys.argv) > 2 else 8
conns = int(sys.argv[3]) if len(sys.argv) > 3 else 8
hb.ROOT, hb.RULES = tree, tree / 'rules' / 'drl'
os.environ['PYTHONPATH'] = str(tree)
TICK = os.sysconf('SC_CLK_TCK')

def tree_pids(root):
    kids = collections.defaultdict(list)
    for p in os.listdir('/proc'):
        if p.isdigit():
            try:
                ppid = int(open(f'/proc/{p}/stat').read().rsplit(')', 1)[1].split()[1])
                kids[ppid].append(int(p))
            except OSError:
                pass
    out, todo = [], [root]
    while todo:
        p = todo.pop(); out.append(p); todo += kids[p]
    return out

def threads(root):
    """{(process comm, thread label): cpu seconds}"""
    cpu = collections.Counter()
    for pid in tree_pids(root):
        try:
            pcomm = open(f'/proc/{pid}/comm').read().strip()
            cmd = open(f'/proc/{pid}/cmdline').read().replace('\0', ' ')
            pname = 'db' if 'secantus' in cmd else 'shipper' if 'shipper' in cmd else 'worker' if 'gateway.worker' in cmd else 'serve' if 'cli' in cmd else pcomm
            for tid in os.listdir(f'/proc/{pid}/task'):
                st = open(f'/proc/{pid}/task/{tid}/stat').read()
                comm = st[st.index('(') + 1:st.rindex(')')]
                f = st.rsplit(')', 1)[1].split()
                label = 'MAIN(loop)' if int(tid) == pid else comm
                label = ''.join('#' if c.isdigit() else c for c in label)
                cpu[(pname, label)] += (int(f[11]) + int(f[12])) / TICK
        except OSError:
            pass
    return cpu

facts = hb.teahouse_facts()
fire = hb.request_bytes('POST', '/api/rulesets/reception/fire', json.dumps({'facts': facts}).encode())
work = Path(tempfile.mkdtemp())
port = hb.free_port()
server = hb.start_server(work / 'server', port, record_fires=True, workers=1)
try:
    asyncio.run(hb.drive(port, fire, hb.WARM_UP_LOAD_S, conns, b'"decision_id"'))
    async def window():
        lat = []
        b = threads(server.pid); t = time.perf_counter()
        errs = await asyncio.gather(*(hb.one_connection(port, fire, t + secs, lat, b'"decision_id"') for _ in range(conns)))
        el = time.perf_counter() - t; a = threads(server.pid)
        return b, a, lat, el, sum(errs)
    before, after, lat, elapsed, errors = asyncio.run(window())
    lat.sort()
    r = {'rps': len(lat) / elapsed, 'p99_ms': lat[int(len(lat) * 0.99)] * 1000, 'n': len(lat), 'errors': errors}
finally:
    server.terminate(); server.wait(timeout=60)
n = r['n']
d = {k: after[k] - before.get(k, 0) for k in after}
total = sum(d.values())
# drive() spends 3 s warming one connection before the measured window: count those requests too
print(f"RESULT {json.dumps({'tree': tree.name, 'rps': round(r['rps'], 1), 'p99': round(r['p99_ms'], 2), 'errors': r['errors'], 'cpu_ms_per_req': round(total / n * 1000, 3), 'load': os.getloadavg()[0]})}")
for k, v in sorted(d.items(), key=lambda x: -x[1])[:14]:
    if v > 0: print(f'   {k[0]:8s} {k[1]:22s} {v:7.2f} s  {v / n * 1000:7.3f} ms/req')
