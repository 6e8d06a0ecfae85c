"""Two chain campaigns over the same downlink files, compared chain by chain: final hazcam answers, within 4 px,
median, chain GO and GO misses, and every chain whose final answer changed (docs/stereo-and-tracking.md).

    python docs/scripts/chain_campaign_compare.py "BEFORE/records/*.jsonl" AFTER
"""
import json, glob, sys
def load(pattern):
    out = {}
    for f in sorted(glob.glob(pattern)):
        path = None; ch = []
        for l in open(f):
            d = json.loads(l)
            if d['kind'] == 'downlink':
                path = d['job']['path']; fam = d['family']
            elif d['kind'] == 'chain':
                ch.append(d['record'])
        if path is None: continue
        for r in ch:
            out.setdefault((path, r['target']), (fam, r))
    return out
old = load(sys.argv[1])
new = load(sys.argv[2] + '/records/*.jsonl')
keys = sorted(set(old) & set(new))
def final(r):
    h = [s for s in r.get('steps', []) if s['camera'] == 'hazcam' and s['extra'].get('final')]
    return h[-1] if h else None
def stats(d, keys):
    n = len(keys); ans = w4 = go = gomiss = far = 0; errs = []
    for k in keys:
        fam, r = d[k]; f = final(r)
        if f is not None and f['tracked_uv'] is not None:
            ans += 1; e = f['error_px']; errs.append(e)
            w4 += e is not None and e <= 4
            far += f['extra'].get('navcam') == 'far' and f['extra'].get('reference') != None and 'far' == f['extra'].get('navcam')
        go += bool(r.get('go')); gomiss += bool(r.get('go')) and not (f and f['error_px'] is not None and f['error_px'] <= 4)
    import statistics
    return dict(chains=n, answered=ans, within4=w4, pct=round(100*w4/n,1), median=round(statistics.median(errs),2) if errs else None, chain_go=go, go_miss=gomiss, far_view=far)
print("old", stats(old, keys)); print("new", stats(new, keys))
fams = sorted({old[k][0] for k in keys})
for fm in fams:
    ks = [k for k in keys if old[k][0] == fm]
    print(fm, "old", stats(old, ks)['within4'], "new", stats(new, ks)['within4'], "of", len(ks))
# per-chain changes
for k in keys:
    fo, fn = final(old[k][1]), final(new[k][1])
    eo = None if fo is None else fo['error_px']; en = None if fn is None else fn['error_px']
    if (eo is None) != (en is None) or (eo is not None and abs(eo - en) > 0.05):
        print(k[0].split('scenes/')[-1], k[1], "old", None if eo is None else round(eo, 2), "new", None if en is None else round(en, 2), fn and fn['extra'].get('navcam'), fn and round(fn['p_success'] or 0, 2), fn and fn['go'])
