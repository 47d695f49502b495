#!/usr/bin/env python3
"""Helpers of scripts/cluster_test.sh (standard library only).

  receiver PORTFILE LOG [PIDDIR]
                             webhook receiver on 127.0.0.1 (a free port, written to PORTFILE):
                             one JSON line per request arrival ("recv") and per 2xx answer
                             written ("ok"), with the Gearwear-Delivery id, the event, the
                             signature header, the body, the sender's port and which replica
                             sent it (PIDDIR/replica-N.pid files, as cluster.sh writes them).
                             GET /_hang?on=1 makes later deliveries wait (at most 25 s) until
                             GET /_hang?on=0 or GET /_release?d=DELIVERY_ID (that one only),
                             then they are answered 200.
  race URL_A URL_B KEY BODY TRIALS
                             TRIALS times: one new Idempotency-Key, the same record POSTed to
                             both replicas at once (a barrier); prints a JSON summary.
  ingest URL KEY BODY RECORDS CLIENTS OUT [MACHINES [PREFIX]]
                             RECORDS records for MACHINES machines PREFIX-0… (default 4,
                             kill-0…, in turn), each
                             with its own Idempotency-Key, from CLIENTS
                             threads; a request without a 2xx answer (502, connection reset…)
                             is sent again with the same key, at most 40 times, 0.25 s apart.
                             OUT gets one JSON line per acknowledged record; prints a summary.
                             With INGEST_UNTIL=FILE in the environment, RECORDS is a minimum:
                             it goes on until FILE exists (so a fast machine cannot finish
                             before the faults it is meant to see).
  deliveries LOG SECRET      checks the receiver's log: every 2xx-answered delivery id once,
                             every signature valid; prints a JSON summary.
  cpu PID…                   user+system CPU seconds of each given process (JSON object),
                             from /proc/PID/stat; missing processes are left out.
  machine_cpu                busy and total CPU seconds of the whole machine (/proc/stat) and
                             the time of day.
"""
import hashlib
import hmac
import itertools
import json
import os
import select
import socket
import sys
import threading
import time
import urllib.error
import urllib.request
import uuid
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

TICK = os.sysconf("SC_CLK_TCK")


def post(url, key, body, idem, timeout=30):
    req = urllib.request.Request(url, data=body, method="POST")
    req.add_header("Authorization", f"Bearer {key}")
    req.add_header("Content-Type", "application/octet-stream")
    req.add_header("Idempotency-Key", idem)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, r.read(), r.headers.get("idempotent-replayed")
    except urllib.error.HTTPError as e:
        return e.code, e.read(), e.headers.get("idempotent-replayed")
    except Exception as e:  # connection refused / reset, timeout
        return None, repr(e).encode(), None


def owner(peer_port, my_port, piddir):
    """The replica (number, from PIDDIR/replica-N.pid) whose socket is the other end of this
    connection: /proc/net/tcp gives the socket's inode, /proc/PID/fd the process holding it."""
    inode = None
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = open(table).readlines()[1:]
        except OSError:
            continue
        for l in lines:
            f = l.split()
            if (int(f[1].rsplit(":", 1)[1], 16) == peer_port
                    and int(f[2].rsplit(":", 1)[1], 16) == my_port):
                inode = f[9]
                break
        if inode:
            break
    if not inode or not piddir:
        return None
    want = f"socket:[{inode}]"
    for name in os.listdir(piddir):
        if not (name.startswith("replica-") and name.endswith(".pid")):
            continue
        try:
            pid = open(os.path.join(piddir, name)).read().strip()
            for fd in os.listdir(f"/proc/{pid}/fd"):
                if os.readlink(f"/proc/{pid}/fd/{fd}") == want:
                    return {"replica": int(name[8:-4]), "pid": int(pid)}
        except OSError:
            continue
    return None


def receiver(portfile, logpath, piddir=None):
    lock = threading.Lock()
    release = threading.Event()
    release.set()
    waiting = {}  # delivery id → Event, for deliveries held in hang mode
    out = open(logpath, "a", buffering=1)

    def log(**kw):
        kw["t"] = time.time()
        with lock:
            out.write(json.dumps(kw) + "\n")

    class H(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, *a):
            pass

        def reply(self, code, text=b"ok"):
            self.send_response(code)
            self.send_header("Content-Length", str(len(text)))
            self.end_headers()
            self.wfile.write(text)
            self.wfile.flush()

        def do_GET(self):
            if self.path.startswith("/_hang"):
                with lock:
                    if self.path.endswith("on=1"):
                        release.clear()
                    else:
                        release.set()
                        for ev in waiting.values():
                            ev.set()
                self.reply(200)
            elif self.path.startswith("/_release?d="):
                with lock:
                    ev = waiting.get(self.path.split("=", 1)[1])
                if ev:
                    ev.set()
                self.reply(200 if ev else 404)
            else:
                self.reply(404)

        def do_POST(self):
            n = int(self.headers.get("Content-Length", "0"))
            body = self.rfile.read(n)
            d = self.headers.get("Gearwear-Delivery")
            port = self.client_address[1]
            log(ev="recv", delivery=d, event=self.headers.get("Gearwear-Event"),
                sig=self.headers.get("Gearwear-Signature"), body=body.decode(), port=port,
                sender=owner(port, self.server.server_address[1], piddir))
            with lock:
                ev = None if release.is_set() else threading.Event()
                if ev:
                    waiting[d] = ev
            if ev:
                ev.wait(25)
                # A sender killed meanwhile has closed its end: writing would still succeed
                # (into the socket buffer), so look for the end of stream first.
                r, _, _ = select.select([self.connection], [], [], 0)
                if r and self.connection.recv(1, socket.MSG_PEEK) == b"":
                    log(ev="gone", delivery=d, port=port)
                    self.close_connection = True
                    return
            try:
                self.reply(200)
                log(ev="ok", delivery=d, port=port)
            except OSError as e:
                log(ev="broken", delivery=d, port=port, error=repr(e))

    srv = ThreadingHTTPServer(("127.0.0.1", 0), H)
    srv.daemon_threads = True
    with open(portfile + ".tmp", "w") as f:
        f.write(str(srv.server_address[1]))
    os.rename(portfile + ".tmp", portfile)
    srv.serve_forever()


def race(url_a, url_b, key, body_path, trials):
    body = open(body_path, "rb").read()
    path = "/v1/machines/race-1/records?sample_rate_hz=25600"
    res = {"trials": trials, "both_2xx": 0, "same_body": 0, "one_replayed": 0,
           "both_fresh": 0, "record_ids": [], "failures": []}
    for n in range(trials):
        idem = f"race-{uuid.uuid4()}"
        out = [None, None]
        barrier = threading.Barrier(2)

        def go(i, url):
            barrier.wait()
            out[i] = post(url + path, key, body, idem)

        ts = [threading.Thread(target=go, args=(i, u)) for i, u in enumerate((url_a, url_b))]
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        (sa, ba, ra), (sb, bb, rb) = out
        if sa == 201 and sb == 201:
            res["both_2xx"] += 1
        if ba == bb:
            res["same_body"] += 1
        replayed = [r == "true" for r in (ra, rb)]
        if sum(replayed) == 1:
            res["one_replayed"] += 1
        if not any(replayed):
            res["both_fresh"] += 1
        if sa != 201 or sb != 201 or ba != bb:
            res["failures"].append({"trial": n, "a": [sa, ba[:200].decode(errors="replace")],
                                    "b": [sb, bb[:200].decode(errors="replace")]})
        try:
            res["record_ids"].append(json.loads(ba)["record_id"])
        except Exception:
            pass
    res["distinct_record_ids"] = len(set(res.pop("record_ids")))
    print(json.dumps(res))


def ingest(url, key, body_path, records, clients, out_path, machines=4, prefix="kill"):
    body = open(body_path, "rb").read()
    run = uuid.uuid4().hex[:8]
    lock = threading.Lock()
    out = open(out_path, "w", buffering=1)
    statuses = {}
    counters = {"sent": 0, "acked": 0, "resends": 0, "replayed_acks": 0, "given_up": 0}
    until = os.environ.get("INGEST_UNTIL")
    nxt = itertools.count()
    t0 = time.time()

    def worker(c):
        while True:
            with lock:
                n = next(nxt)
                if n >= records and not (until and not os.path.exists(until)):
                    return
                counters["sent"] = n + 1
            idem = f"kill-{run}-{n}"
            path = f"/v1/machines/{prefix}-{n % machines}/records?sample_rate_hz=25600"
            for attempt in range(40):
                st, b, replayed = post(url + path, key, body, idem)
                with lock:
                    k = str(st)
                    statuses[k] = statuses.get(k, 0) + 1
                    if attempt:
                        counters["resends"] += 1
                if st is not None and 200 <= st < 300:
                    j = json.loads(b)
                    with lock:
                        counters["acked"] += 1
                        if replayed == "true":
                            counters["replayed_acks"] += 1
                        out.write(json.dumps({"key": idem, "record_id": j["record_id"],
                                              "diagnosis_id": j["id"], "attempts": attempt + 1,
                                              "replayed": replayed == "true",
                                              "t": time.time() - t0}) + "\n")
                    break
                time.sleep(0.25)
            else:
                with lock:
                    counters["given_up"] += 1

    ts = [threading.Thread(target=worker, args=(c,)) for c in range(clients)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    counters["statuses"] = statuses
    counters["seconds"] = round(time.time() - t0, 1)
    print(json.dumps(counters))


def deliveries(logpath, secret):
    recv, ok = {}, {}
    bad_sig = 0
    for line in open(logpath):
        e = json.loads(line)
        d = e["delivery"]
        if e["ev"] == "recv":
            recv[d] = recv.get(d, 0) + 1
            t, v1 = (p.split("=", 1)[1] for p in e["sig"].split(","))
            mac = hmac.new(secret.encode(), f"{t}.".encode() + e["body"].encode(),
                           hashlib.sha256).hexdigest()
            if not hmac.compare_digest(v1, mac):
                bad_sig += 1
        elif e["ev"] == "ok":
            ok[d] = ok.get(d, 0) + 1
    print(json.dumps({
        "received_requests": sum(recv.values()), "distinct_received": len(recv),
        "answered_2xx": sum(ok.values()), "distinct_answered_2xx": len(ok),
        "answered_more_than_once": sum(1 for v in ok.values() if v > 1),
        "received_more_than_once": sum(1 for v in recv.values() if v > 1),
        "bad_signatures": bad_sig}))


def cpu(pids):
    out = {}
    for p in pids:
        try:
            s = open(f"/proc/{p}/stat").read()
        except OSError:
            continue
        f = s[s.rfind(")") + 2:].split()
        out[p] = (int(f[11]) + int(f[12])) / TICK
    print(json.dumps(out))


def machine_cpu():
    f = [int(x) for x in open("/proc/stat").readline().split()[1:]]
    idle = f[3] + f[4]
    print(f"{(sum(f[:8]) - idle) / TICK:.2f} {sum(f[:8]) / TICK:.2f} {time.time():.3f}")


if __name__ == "__main__":
    cmd, a = sys.argv[1], sys.argv[2:]
    if cmd == "receiver":
        receiver(*a)
    elif cmd == "race":
        race(a[0], a[1], a[2], a[3], int(a[4]))
    elif cmd == "ingest":
        ingest(a[0], a[1], a[2], int(a[3]), int(a[4]), a[5], int(a[6]) if len(a) > 6 else 4,
               a[7] if len(a) > 7 else "kill")
    elif cmd == "deliveries":
        deliveries(a[0], a[1])
    elif cmd == "cpu":
        cpu(a)
    elif cmd == "machine_cpu":
        machine_cpu()
    else:
        sys.exit(__doc__)
