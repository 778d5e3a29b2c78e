#!/usr/bin/env python3
"""Lists every unwrap/expect/assert/panic/unreachable in non-test code (src/ and crates/*/src,
excluding tests.rs files and #[cfg(test)] modules): the starting point of the audit in
docs/LIMITS.md ("Panics"). Run from the repository root: python3 scripts/panic_audit.py"""
import os,re,sys
pat=re.compile(r'\.unwrap\(\)|\.expect\(|\bassert!|\bassert_eq!|\bassert_ne!|\bpanic!|\bunreachable!|\btodo!|\bunimplemented!')
res=[]
for root in ['src']+[os.path.join('crates',c,'src') for c in os.listdir('crates')]:
    for dp,dn,fn in os.walk(root):
        for f in fn:
            if not f.endswith('.rs') or f == 'tests.rs': continue
            p=os.path.join(dp,f)
            lines=open(p).read().split('\n')
            in_test=False
            for i,l in enumerate(lines):
                if re.match(r'\s*#\[cfg\(test\)\]',l): in_test=True
                if in_test: break
                s=l.strip()
                if s.startswith('//'): continue
                if pat.search(l): res.append((p,i+1,s))
for r in res: print(f"{r[0]}:{r[1]}: {r[2]}")
print(f'{len(res)} sites', file=sys.stderr)
