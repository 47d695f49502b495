#!/usr/bin/env python3
"""Replay the closed loop's selection over the stored candidates of benchmark rows.

`benches/closed_loop.rs` stores each record's candidates (its rows: `CL_OUT`, by default
`target/bench/closed_loop.json` or `$CARGO_TARGET_DIR/bench/closed_loop.json`; since session 14
with the reasons a candidate was refused and a pair's member shares). The selection of
`closed_loop::calibrate` depends on nothing else, so a rule of the selection can be changed
here and its effect on naming, false claims, clean and non-library records read off without
simulating anything again. This reproduces the stored answers exactly at the rules the rows
were made with (it prints `same` = records whose answer is unchanged); a rule replayed here is
a hypothesis to measure on fresh seeds with the real code, not a result.

    scripts/closed_loop_replay.py ROWS.json [ROWS.json …] [--min-col N] [--sm-alt DB]
        [--sm-wide] [--share S] [--tooth F] [--margin M] [--null-z Z] [--verbose]

--min-col N    a path resonance must colour N of the plain model's lines (as the rows were
               made: the count is read from the refusal's text);
--sm-alt DB    a single shaft modulation below the share is eligible where its shaft's
               sidebands are at its rate DB above the window's median and it beats "no effect"
               by 2 claim margins;
--sm-wide      a modulation's share on sideband orders ±1–3 (only in rows of the session-14
               diagnostic build, whose candidates carry it as an 8th element);
--share S      the fingerprint share needed (0.25);
--tooth F      the tooth-damage margin factor (2.5);
--margin M, --null-z Z   the claim margin M + Z · null spread (as stored: 50 + 0.5 spread);
--band-k K     a path resonance its own band supports (rows since session 15: the candidates'
               8th element, `BandEvidence`) stands alone if it beats "no effect" by K claim
               margins (2); --band-n N, --band-frac F set what "supports" means (8, 0.8);
--no-band      the selection before session 15 (the band ignored);
--ceiling      also count, per visible library effect, whether its own best single candidate
               beats "no effect" at all and by the claim margin (× the tooth factor for tooth
               damage): what any selection on these candidates could name with that margin.
"""
import argparse
import json
import re

LIB = {'path-resonance', 'shaft-modulation', 'tooth-damage', 'planetary-wear'}
# The virtual rig's shafts: the input (f1/29) and the stage-1 gear's (f1/100).
SHAFT = {'0.0345': 'motor', '0.0100': 'B'}


def sm_shaft(r, i):
    """The shaft of single shaft-modulation candidate i: fastest first, as calibrate tries them."""
    sm = [j for j, c in enumerate(r['candidates']) if c[0] == 'shaft-modulation']
    return '0.0345' if sm and i == sm[0] else '0.0100'


def band_holds(c, P):
    """The resonance's half-power band holds it (`BandEvidence::holds`)."""
    if P['no_band'] or len(c) < 8:
        return False
    b = c[7]
    if isinstance(b, dict):
        b = [b['points'], b['improved'], b['share']]
    if not isinstance(b, list):
        return False
    n, imp, share = b
    return n >= P['band_n'] and imp >= P['band_frac'] * n and share >= P['share']


def decide(r, P):
    cands = r['candidates']
    if not cands:
        return r['named']
    margin = r['claim_margin']
    if P.get('margin') is not None:
        margin = P['margin'] + P['null_z'] * r['null_spread']
    err0 = r['error_before']
    sb = {s[0]: s for s in r['sidebands']}
    S = P['share']

    def band_stands(i):
        c = cands[i]
        return band_holds(c, P) and ('+' in c[0] or c[1] < -P['band_k'] * margin)

    def elig(i):
        if i == 0:
            return False
        c = cands[i]
        name, dbic, _el, share, err, refused, _members = c[:7]
        effs = name.split('+')
        sh = share
        if P['sm_wide'] and 'shaft-modulation' in effs and len(c) > 7 \
                and isinstance(c[7], (int, float)):
            sh = c[7]
        if sh is None or sh < S:
            ok = False
            if P['sm_alt'] is not None and effs == ['shaft-modulation']:
                s = sb.get(SHAFT.get(sm_shaft(r, i)))
                ok = (s is not None and len(s) > 5 and s[5] and not s[3]
                      and s[4] >= P['sm_alt'] and dbic < -2.0 * margin)
            if effs == ['path-resonance'] and band_stands(i):
                ok = True
            if not ok:
                return False
        for msg in refused:
            if msg.startswith('the resonance moves'):
                if band_stands(i):
                    continue
                if int(re.search(r'moves (\d+) of', msg).group(1)) < P['min_col']:
                    return False
            else:
                return False
        return err <= err0 + 1e-9

    def mfac(i):
        return P['tooth'] if 'tooth-damage' in cands[i][0] else 1.0

    singles = [i for i in range(1, len(cands)) if '+' not in cands[i][0]]
    pairs = [i for i in range(1, len(cands)) if '+' in cands[i][0]]
    ok_s = [i for i in singles if elig(i) and cands[i][1] < -margin * mfac(i)]
    if not ok_s:
        return []
    chosen = single = min(ok_s, key=lambda i: cands[i][1])
    ok_p = [i for i in pairs if elig(i)]
    if ok_p:
        pair = min(ok_p, key=lambda i: cands[i][1])
        ms = cands[pair][6]

        def supported(name):
            return any(cands[i][0] == name and cands[i][1] < 0 and elig(i) for i in singles)

        members = cands[pair][0].split('+')
        if all(supported(n) or (k < len(ms) and ms[k] >= S)
               or (n == 'path-resonance' and band_stands(pair))
               for k, n in enumerate(members)) \
                and cands[pair][1] < cands[single][1] - margin * mfac(pair):
            chosen = pair
    return cands[chosen][0].split('+')


def visible_effects(r):
    if r['kind'] == 'pair':
        return [m[0] for m in r['member_visible_k'] if m[1]]
    return list(r['truth']) if r['visible_k'] else []


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('rows', nargs='+')
    ap.add_argument('--min-col', type=int, default=2)
    ap.add_argument('--sm-alt', type=float, default=None)
    ap.add_argument('--sm-wide', action='store_true')
    ap.add_argument('--share', type=float, default=0.25)
    ap.add_argument('--tooth', type=float, default=2.5)
    ap.add_argument('--margin', type=float, default=None,
                    help='claim margin before its null part (50; default: as stored)')
    ap.add_argument('--null-z', type=float, default=0.5)
    ap.add_argument('--band-k', type=float, default=2.0)
    ap.add_argument('--band-n', type=int, default=8)
    ap.add_argument('--band-frac', type=float, default=0.8)
    ap.add_argument('--no-band', action='store_true')
    ap.add_argument('--ceiling', action='store_true')
    ap.add_argument('--verbose', action='store_true')
    a = ap.parse_args()
    P = dict(min_col=a.min_col, sm_alt=a.sm_alt, sm_wide=a.sm_wide, share=a.share, tooth=a.tooth,
             margin=a.margin, null_z=a.null_z, band_k=a.band_k, band_n=a.band_n,
             band_frac=a.band_frac, no_band=a.no_band)
    rows = [r for f in a.rows for r in json.load(open(f)) if not r.get('error')]
    if any(len(r['candidates'][0]) < 7 for r in rows if r['candidates']):
        raise SystemExit('rows older than session 14 (no refusal reasons): cannot replay')
    eff = [0, 0]
    per = {}
    false_lib = clean_ok = n_clean = non_ok = n_non = same = 0
    for r in rows:
        named = decide(r, P)
        same += sorted(named) == sorted(r['named'])
        if a.verbose and sorted(named) != sorted(r['named']):
            print(f"  changed {r['seed']}:{r['index']} {r['kind']} truth {r['truth']}: "
                  f"{r['named']} -> {named}")
        k = r['kind']
        if k in LIB or k == 'pair':
            for v in visible_effects(r):
                eff[1] += 1
                eff[0] += v in named
                p = per.setdefault(v, [0, 0])
                p[1] += 1
                p[0] += v in named
            false_lib += any(x not in r['truth'] for x in named)
        elif k == 'clean':
            n_clean += 1
            clean_ok += not named
        else:
            n_non += 1
            non_ok += not named and (r['unexplained'] > 0 or not r['visible_k'])
    pct = lambda x, n: f"{100 * x / max(n, 1):.0f} % ({x}/{n})"
    print(f"records {len(rows)}, answer unchanged {same}")
    print(f"visible library effects named: {pct(*eff)}; "
          + ', '.join(f"{k} {x}/{n}" for k, (x, n) in sorted(per.items())))
    print(f"library records with a false claim: {false_lib}")
    print(f"clean, nothing claimed: {pct(clean_ok, n_clean)}")
    print(f"non-library kept out: {pct(non_ok, n_non)}")
    if a.ceiling:
        n = beats = by_margin = 0
        for r in rows:
            if r['kind'] not in LIB and r['kind'] != 'pair':
                continue
            for v in visible_effects(r):
                own = [c[1] for c in r['candidates'] if c[0] == v]
                if not own:
                    continue
                n += 1
                fac = a.tooth if v == 'tooth-damage' else 1.0
                beats += min(own) < 0
                by_margin += min(own) < -r['claim_margin'] * fac
        print(f"ceiling: the true effect's own single beats \"no effect\" {pct(beats, n)}, "
              f"by the claim margin {pct(by_margin, n)}")


if __name__ == '__main__':
    main()
