#!/usr/bin/env python3
"""Score Model A parameter variants against the first seed's reported chaos windows.

Usage (from the repo root, after `cargo build --release`):
    python3 scripts/calibrate_model_a.py '[{"static_load":0.15},{"static_load":0.2,"fluctuation":0.3}]'

Each variant rewrites keys of configs/model_a.toml, runs `gearwear bifurcation` at
ea = 0.1, 0.2, 0.4, 0.8, 1 over Ω1 = 0.02…3 (step 0.02) and scores eight criteria taken from
model.md findings 1–3, each a fraction in [0, 1] (8 = every window as the paper reports it).
It prints one JSON line per variant. Variants are written to a temporary directory.
"""
import tempfile, os
import subprocess, csv, io, itertools, sys, re, json
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
base = open(os.path.join(ROOT, 'configs/model_a.toml')).read()
BIN = os.path.join(ROOT, 'target/release/gearwear')
TMP = tempfile.mkdtemp()
def sweep(cfgpath, ea, step=0.02, end=3.0):
    out = subprocess.run([BIN,'bifurcation','--config',cfgpath,'--ea',str(ea),'--omega1',f'0.02:{end}:{step}','--elements','x1'],capture_output=True,text=True,check=True).stdout
    st={}
    for r in csv.DictReader(io.StringIO(out)): st[float(r['omega1'])]=r['state']
    return st
def frac(st, lo, hi, pred):
    ks=[k for k in st if lo<=k<=hi]
    return sum(pred(st[k]) for k in ks)/max(1,len(ks))
ch=lambda s: s=='chaotic'
def score(cfg):
    s={}
    st=sweep(cfg,0.1); s['ea0.1 no chaos <3']=1-frac(st,0.02,3,ch); s['ea0.1 p1 <0.9']=frac(st,0.02,0.9,lambda x:x=='period-1')
    st=sweep(cfg,0.2); s['ea0.2 chaos near 1.5']=min(1,3*frac(st,1.3,1.7,ch)); s['ea0.2 not all chaos']=1-frac(st,0.5,1.6,ch)
    st=sweep(cfg,0.4); s['ea0.4 chaos .5-1.6']=frac(st,0.5,1.6,ch)
    st=sweep(cfg,0.8); s['ea0.8 reg .5-.85']=1-frac(st,0.5,0.85,ch); s['ea0.8 chaos .85-1.6']=frac(st,0.85,1.6,ch)
    st=sweep(cfg,1.0); s['ea1 chaos .9-1.6']=frac(st,0.9,1.6,ch)
    return s
def variant(**kw):
    t=base
    for k,v in kw.items():
        t=re.sub(rf'^{k} = .*$', f'{k} = {v}', t, flags=re.M)
    return t
grid=json.loads(sys.argv[1])
for i,kw in enumerate(grid):
    p=os.path.join(TMP, f'v{i}.toml'); open(p,'w').write(variant(**kw))
    s=score(p)
    print(json.dumps(kw), round(sum(s.values()),2), {k:round(v,2) for k,v in s.items()}, flush=True)
