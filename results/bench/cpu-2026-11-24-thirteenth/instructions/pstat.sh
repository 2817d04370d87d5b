for R in 1 41; do R=$R perf stat -e cycles,instructions,branch-misses -x, -o /tmp/cb/stat$R.txt python /tmp/cb/climbbench.py 2>&1 | tail -1; done
python - <<'P'
def rd(f):
    d={}
    for l in open(f):
        if l.startswith('#') or ',' not in l: continue
        x=l.split(','); d[x[2]]=float(x[0])
    return d
a,b=rd('/tmp/cb/stat1.txt'),rd('/tmp/cb/stat41.txt')
beams=(510*6+30)*180
for k in a: print(k, f"{(b[k]-a[k])/40:.3g} per match, {(b[k]-a[k])/40/beams:.1f} per beam eval")
P
