"""The deck-future teacher alone on the evaluation seeds; docs/experiments/lander.md."""
import os, sys, time, numpy as np
sys.argv=[sys.argv[0]]
os.environ.setdefault("TEACHER","truth")
exec(open("benchmarks/lander_dagger.py").read().split("seed = 100_000")[0])
outs=[];durs=[]
for s in range(int(os.environ.get("N","30"))):
    venv.seed(4_000_000+s); obs=venv.reset(); expert.reset(); k=0; kd=None
    while True:
        raw={kk: obs[kk][0][..., -w:] for kk,w in widths.items()}
        a=np.asarray(expert.act(raw),dtype=np.float32)
        if kd is None and expert.phase.value=="descent": kd=k
        obs,_,done,info=venv.step(a[None]); k+=1
        if done[0]:
            outs.append(info[0]["outcome"]); durs.append((k-kd)*0.05 if kd is not None else -1); break
print("teacher", os.environ["TEACHER"], os.environ.get("LEAD"), {o:outs.count(o) for o in set(outs)}, "descent s", np.percentile([d for d in durs if d>0],[5,50,95]))
