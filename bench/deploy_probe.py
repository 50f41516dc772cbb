"""Deploy memory probe: an in-process Engine deploys new contents of a small rule set N, then 2N
times (each fired), and prints the compiled rule sets kept alive, the JVM's non-heap and classes,
the heap, and tracemalloc's biggest growths between N and 2N (docs/benchmarks.md "Soak").

    PYTHONPATH=. .venv/bin/python bench/deploy_probe.py 30
"""
import gc, sys, time, tempfile, tracemalloc
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "engine"))
from engine_samples import TYPES, RULES
from gateway.config import Settings
from gateway.engine import Engine
from gateway.engine.compiler import CompiledRuleSet
from gateway.base import jvm
import jpype

N = int(sys.argv[1]) if len(sys.argv) > 1 else 40
root = Path(tempfile.mkdtemp())
engine = Engine(Settings(data_dir=str(root / "data"), engine={"rules_dir": str(root / "rules")}))
facts = [{"type": "Customer", "id": "c1", "age": 30, "gender": "f", "distance": 1.0}]
def deploy(i):
    engine.deploy("t", {"types.drl": TYPES, "rules.drl": RULES.replace("Hello ", f"Hello{i} ")})
    engine.fire("t", facts)
def state(tag):
    gc.collect(); jpype.JClass("java.lang.System").gc(); time.sleep(0.5)
    alive = sum(1 for o in gc.get_objects() if isinstance(o, CompiledRuleSet))
    print(tag, "compiled alive", alive, "non_heap", jvm.non_heap(), "heap", jvm.heap(), "pyobjs", len(gc.get_objects()), flush=True)
deploy(0)
state("after 1")
tracemalloc.start(10)
for i in range(1, N): deploy(i)
state(f"after {N}")
s1 = tracemalloc.take_snapshot()
for i in range(N, 2*N): deploy(i)
state(f"after {2*N}")
s2 = tracemalloc.take_snapshot()
for st in s2.compare_to(s1, "lineno")[:12]: print(st)
