#!/usr/bin/env python3
"""Seeds fuzz/corpus/live_wire: valid asks (still, small grids, one in three
parts; parts out of order, repeated, missing; a flow larger than the
harness's store; heads out of range) and pair heads, then bit flips,
truncations and insertions of the small ones, 64 inputs in all. A fuzz run
with --grow adds what it finds (fuzz/run.sh). Deterministic: seeded."""
import struct, hashlib, os, random
rnd=random.Random(55)
out=os.path.join(os.path.dirname(os.path.abspath(__file__)), 'corpus', 'live_wire')
def ask(from_pair, reach, seps, nx, ny, x0, y0, pitch, row0, rows, seed=0, count=None):
    c=len(seps) if count is None else count
    h=struct.pack('<IHBB', from_pair, reach, c, 0)
    s=(list(seps)+[0]*8)[:8]
    h+=struct.pack('<8H', *s)
    h+=struct.pack('<HHiiHH', nx, ny, x0, y0, pitch, row0)
    r=random.Random(seed)
    body=b''.join(struct.pack('<4h', *[r.randint(-32768,32767) for _ in range(4)]) for _ in range(nx*rows))
    return h+body
def framed(parts):
    return b''.join(struct.pack('<H', len(p))+p for p in parts)
inputs=[]
inputs.append(b'\x00'+framed([ask(1, 32, [], 0, 0, 0, 0, 16, 0, 0)]))
inputs.append(b'\x00'+framed([ask(0, 0, [16,32,64], 0, 0, 0, 0, 16, 0, 0)]))
for (nx,ny,pitch) in [(1,1,16),(3,2,256),(8,5,128),(25,16,256),(4,4,4096),(2,3,15),(2,3,4097)]:
    inputs.append(b'\x00'+framed([ask(5, 0, [16,32,64,128], nx, ny, -40, 128, pitch, 0, ny, seed=nx)]))
nx,ny=210,20
parts=[ask(9, 8, [16,32], nx, ny, 0, 0, 128, r0, min(9, ny-r0), seed=r0) for r0 in range(0, ny, 9)]
inputs.append(b'\x00'+framed(parts))
inputs.append(b"\x00"+framed([parts[0], parts[2], parts[1]]))
inputs.append(b'\x00'+framed([parts[0], parts[1], parts[1], parts[2]]))
inputs.append(b'\x00'+framed(parts[:2]))
inputs.append(b'\x00'+framed([ask(2, 0, [16], 70, 70, 0, 0, 64, 0, 29)]))
inputs.append(b'\x00'+framed([ask(1, 0, [0], 2, 2, 0, 0, 64, 0, 2)]))
inputs.append(b'\x00'+framed([ask(1, 0, [16]*8, 2, 2, 0, 0, 64, 0, 2, count=9)]))
inputs.append(b'\x00'+framed([ask(1, 0, [16], 2, 2, 1<<25, 0, 64, 0, 2)]))
inputs.append(b'\x00'+framed([ask(1, 0, [16], 2, 2, 0, 0, 64, 1, 2)]))
def head(pair, mid, fp, seps, ev_first, ev_ticks, offsets, parts=None):
    b=struct.pack('<IIIBBHI', pair, mid, fp, len(seps), 0, ev_ticks, ev_first)
    b+=struct.pack('<8H', *(list(seps)+[0]*8)[:8])
    b+=struct.pack('<16h', *(list(offsets)+[0]*16)[:16])
    p=2*len(seps)+ev_ticks+(1 if ev_ticks else 0) if parts is None else parts
    b+=struct.pack('<HH', p, 0)
    return b
inputs.append(b'\x01'+head(0, 100, 0xffffffff, [], 68, 64, []))
inputs.append(b'\x01'+head(7, 900, 6, [16,32,64,128], 0, 0, [-5,0,-700,3,1,2,3,4]))
inputs.append(b'\x01'+head(7, 900, 6, [16,32,64,128], 836, 128, list(range(8))))
inputs.append(b'\x01'+head(1, 1, 1, [16], 0, 225, []))
inputs.append(b'\x01'+head(1, 1, 1, [16], 0, 10, [], parts=3))
inputs.append(b'\x01'+head(1, 1, 1, [16,0], 0, 10, []))
base=list(inputs)
seen=set(inputs)
while len(seen) < 64:
    b=bytearray(rnd.choice([x for x in base if len(x) < 2000]))
    k=rnd.randrange(3)
    if k==0 and len(b)>1:
        i=rnd.randrange(1,len(b)); b[i]^=1<<rnd.randrange(8)
    elif k==1 and len(b)>2:
        b=b[:rnd.randrange(1,len(b))]
    else:
        i=rnd.randrange(1,len(b)) if len(b)>1 else 1
        b[i:i]=bytes([rnd.randrange(256)])
    seen.add(bytes(b))
for x in seen:
    open(os.path.join(out,hashlib.sha1(x).hexdigest()),'wb').write(x)
print(len(os.listdir(out)))
