"""Fill a bare embedded SecantusDB (256M cache, no gateway) with 2 KB decision-like documents, 1,000
an insert, and print its RSS and files on disk every 20,000: does the database's memory follow
the data it stores (the soak's database growth, docs/benchmarks.md "Soak")?

    .venv/bin/python bench/db_fill.py 400000
"""
import sys, time, tempfile, os
from pathlib import Path
from datetime import datetime, timezone
from gateway.store.embedded import EmbeddedMongo
import pymongo
root = Path(tempfile.mkdtemp())
db = EmbeddedMongo(root, 0, "256M"); uri = db.start()
pid = db.proc.pid
def rss():
    for l in open(f"/proc/{pid}/status"):
        if l.startswith("VmRSS"): return int(l.split()[1]) // 1024
def files():
    return sum(f.stat().st_size for f in (root / "data").rglob("*") if f.is_file()) // 2**20
c = pymongo.MongoClient(uri)["t"]["decisions"]
c.create_index([("ruleset", 1), ("_id", -1)])
payload = "x" * 1800
n, t0 = 0, time.time()
print("docs rss_mb files_mb s", flush=True)
while n < int(sys.argv[1]):
    c.insert_many([{"ruleset": "reception", "k": n + i, "facts": payload, "_meta": {"inserted_at": datetime.now(timezone.utc)}} for i in range(1000)])
    n += 1000
    if n % 20000 == 0:
        print(n, rss(), files(), round(time.time() - t0), flush=True)
db.stop()
