"""A self-contained HTML page that plays a motion on the body mesh (no network, no server).

The page carries the shaped rest mesh, sparse skinning weights (top 4 joints per vertex) and per
frame 24 joint transforms; the browser skins the mesh itself (linear blend skinning, same maths
as :class:`wearpose.body.BodyModel`), so a 10-second clip stays around a megabyte. Drawing is a
plain 2D canvas (painter's algorithm, Lambert shading): no WebGL or 3D library needed, so the
file opens anywhere, including headless browsers in tests.

Every track has its own colour (:mod:`wearpose.viewer.scene`: estimates saturated, the ground
truth grey), named in a legend (``#legend``) and in the label above its head; the sensor dots
are the sites the caller names (a demo: its kit's sensors only). The camera follows the bodies
(it looks at their mean root of the frame shown).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from wearpose.body import PARENTS, BodyModel, forward_kinematics
from wearpose.errors import ShapeError
from wearpose.viewer.scene import PALETTE, Colour

_TOPK = 4


def _b64(a: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def _track(body: BodyModel, pose: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor, label: str,
           shift: float, colour: Colour) -> dict:
    """Per-track arrays: shaped rest mesh, per-frame skinning transforms and joints."""
    with torch.no_grad():
        pose = pose.to(body.dtype)
        b = betas.to(body.dtype)
        v_shaped = body.v_template + torch.einsum("vcs,s->vc", body.shapedirs, b)  # (V, 3)
        J_rest = body.rest_joints(b)  # (24, 3)
        G, J = forward_kinematics(pose, J_rest)  # (T, 24, 3, 3), (T, 24, 3)
        J = J + trans.to(body.dtype)[:, None]
        J[..., 0] += shift  # side-by-side display offset along +X, metres
        t = J - (G @ J_rest.unsqueeze(-1)).squeeze(-1)
        A = torch.cat([G.reshape(*G.shape[:2], 9), t], dim=-1)  # (T, 24, 12)
    return {"label": label, "colour": [int(c) for c in colour], "verts": _b64(v_shaped.cpu().numpy(), "<f4"), "A": _b64(A.cpu().numpy(), "<f4"),
            "joints": _b64(J.cpu().numpy(), "<f4")}


def skinning_payload(body: BodyModel, pose: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor,
                     site_names: Sequence[str] | None = None,
                     compare: Sequence[tuple[str, torch.Tensor, torch.Tensor, torch.Tensor]] = (),
                     label: str = "motion", spacing: float = 1.0,
                     colours: Sequence[Colour] | None = None) -> dict:
    """Arrays the page needs, as a JSON-able dict.

    Args:
        pose: ``(T, 24, 3, 3)`` local rotations; betas ``(S,)``; trans ``(T, 3)`` m.
        site_names: sensor sites drawn on every track (None: all sites of the asset; ``()``: none).
        compare: further tracks ``(label, pose, betas, trans)`` with the same ``T``, drawn beside
            the first one, each ``spacing`` metres further along +X (e.g. ground truth).
        colours: one ``(r, g, b)`` per track, the main track first (default: :data:`PALETTE` in
            order); two tracks may not share one.
    """
    n = 1 + len(compare)
    cols = [tuple(int(c) for c in col) for col in (colours if colours is not None else PALETTE[:n])]
    if len(cols) != n:
        raise ShapeError(f"colours: {len(cols)} given for {n} tracks (one per track, the main track first)")
    if len(set(cols)) != n:
        raise ShapeError(f"colours: tracks must differ in colour, got {cols}")
    tracks = [_track(body, pose, betas, trans, label, 0.0, cols[0])]
    for k, (lab, p2, b2, t2) in enumerate(compare, start=1):
        if p2.shape[0] != pose.shape[0]:
            raise ShapeError(f"compare track {lab!r} has {p2.shape[0]} frames, the main track {pose.shape[0]}")
        tracks.append(_track(body, p2, b2, t2, lab, spacing * k, cols[k]))
    w = body.weights.cpu().numpy()
    idx = np.argsort(-w, axis=1)[:, :_TOPK]
    wk = np.take_along_axis(w, idx, axis=1)
    wk = wk / wk.sum(1, keepdims=True)
    names, vids, _ = body.site_ids(site_names) if body.site_names else ((), np.zeros(0, np.int64), None)
    return {
        "V": body.num_vertices, "F": int(body.faces.shape[0]), "T": int(pose.shape[0]),
        "tracks": tracks, "faces": _b64(body.faces.cpu().numpy(), "<u4"),
        "widx": _b64(idx, "<u1"), "w": _b64(wk, "<f4"), "parents": list(PARENTS),
        "sites": [int(v) for v in vids], "site_names": list(names),
    }


def write_html(path: str | Path, body: BodyModel, pose: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor,
               fps: float, title: str = "wearpose", site_names: Sequence[str] | None = None,
               info: dict | None = None, label: str = "motion",
               compare: Sequence[tuple[str, torch.Tensor, torch.Tensor, torch.Tensor]] = (),
               colours: Sequence[Colour] | None = None, sites_label: str | None = None) -> Path:
    """Write a page that plays ``pose``/``trans`` on ``body``; returns the path.

    Args:
        path: output ``.html``.
        pose: ``(T, 24, 3, 3)`` local joint rotations; betas ``(S,)``; trans ``(T, 3)`` m.
        fps: playback rate (frames per second of the motion).
        site_names: sensor sites to draw (default: all sites of the asset; a demo passes its kit's,
            :func:`wearpose.viewer.scene.kit_sites`).
        info: extra key/values shown in the page header (e.g. metrics).
        label: name of the main track; ``compare``: further ``(label, pose, betas, trans)``
            tracks drawn beside it (e.g. ground truth next to an estimate).
        colours: one per track, main first (default :data:`~wearpose.viewer.scene.PALETTE`).
        sites_label: the sensor dots' legend entry (e.g. "6 IMUs (imu6)"; default "N sensor sites").
    """
    payload = skinning_payload(body, pose, betas, trans, site_names, compare=compare, label=label, colours=colours)
    label_s = sites_label if sites_label is not None else f"{len(payload['sites'])} sensor sites"
    payload.update({"fps": float(fps), "title": title, "info": info or {}, "sites_label": label_s})
    html = _TEMPLATE.replace("__PAYLOAD__", json.dumps(payload)).replace("__TITLE__", title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html, encoding="utf-8")
    return path


_TEMPLATE = r"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>__TITLE__</title>
<style>
body{margin:0;font:13px sans-serif;background:#1d1f24;color:#ddd}
#bar{padding:6px 10px;display:flex;gap:10px;align-items:center;flex-wrap:wrap}
#c{display:block;width:100vw;height:calc(100vh - 40px);cursor:grab}
input[type=range]{flex:1;min-width:200px}
label{white-space:nowrap}
#legend{display:flex;gap:12px;flex-wrap:wrap}
#legend span{white-space:nowrap}
#legend i{display:inline-block;width:12px;height:12px;margin-right:4px;vertical-align:-1px;border-radius:2px}
#legend i.dot{border-radius:6px;border:1px solid #222}
</style></head><body>
<div id="bar"><b id="title"></b><button id="play">pause</button>
<input id="t" type="range" min="0" value="0"><span id="frame"></span>
<label><input id="mesh" type="checkbox" checked>mesh</label>
<label><input id="skel" type="checkbox" checked>skeleton</label>
<label><input id="site" type="checkbox" checked>sensor sites</label>
<span id="legend"></span><span id="info"></span></div>
<canvas id="c" data-frame="-1"></canvas>
<script>
const P = __PAYLOAD__;
function dec(s, T){const b=atob(s);const u=new Uint8Array(b.length);for(let i=0;i<b.length;i++)u[i]=b.charCodeAt(i);return new T(u.buffer);}
const V=P.V,F=P.F,T=P.T, faces=dec(P.faces,Uint32Array), widx=dec(P.widx,Uint8Array), w=dec(P.w,Float32Array);
const TR=P.tracks.map(t=>({label:t.label,col:t.colour,rest:dec(t.verts,Float32Array),A:dec(t.A,Float32Array),J:dec(t.joints,Float32Array)}));
document.getElementById('title').textContent=P.title;
const SITE_COL='#ffd21f';
{const lg=document.getElementById('legend');
 const add=(cls,col,text)=>{const e=document.createElement('span');const i=document.createElement('i');if(cls)i.className=cls;i.style.background=col;e.appendChild(i);e.appendChild(document.createTextNode(text));lg.appendChild(e);};
 for(const tr of TR)add('',`rgb(${tr.col[0]},${tr.col[1]},${tr.col[2]})`,tr.label);
 if(P.sites.length)add('dot',SITE_COL,P.sites_label);}
document.getElementById('info').textContent=Object.entries(P.info).map(([k,v])=>k+': '+v).join('  ');
const slider=document.getElementById('t'); slider.max=T-1;
const cv=document.getElementById('c'), ctx=cv.getContext('2d');
let yaw=0.5, pitch=0.15, dist=3.2, playing=true, frame=0, t0=performance.now();
let drag=null;
cv.onmousedown=e=>{drag=[e.clientX,e.clientY,yaw,pitch]};
window.onmouseup=()=>drag=null;
window.onmousemove=e=>{if(drag){yaw=drag[2]+(e.clientX-drag[0])*0.01;pitch=Math.max(-1.4,Math.min(1.4,drag[3]+(e.clientY-drag[1])*0.01));draw();}};
cv.onwheel=e=>{dist*=Math.exp(e.deltaY*0.001);e.preventDefault();draw();};
document.getElementById('play').onclick=()=>{playing=!playing;document.getElementById('play').textContent=playing?'pause':'play';t0=performance.now()-frame*1000/P.fps;};
slider.oninput=()=>{frame=+slider.value;t0=performance.now()-frame*1000/P.fps;draw();};
for(const id of ['mesh','skel','site'])document.getElementById(id).onchange=draw;
const pv=new Float32Array(V*3);
function skin(tr,f){const a=tr.A.subarray(f*288,(f+1)*288),rest=tr.rest;
 for(let v=0;v<V;v++){let x=0,y=0,z=0;const rx=rest[3*v],ry=rest[3*v+1],rz=rest[3*v+2];
  for(let k=0;k<4;k++){const wt=w[4*v+k];if(wt===0)continue;const m=12*widx[4*v+k];
   x+=wt*(a[m]*rx+a[m+1]*ry+a[m+2]*rz+a[m+9]);y+=wt*(a[m+3]*rx+a[m+4]*ry+a[m+5]*rz+a[m+10]);z+=wt*(a[m+6]*rx+a[m+7]*ry+a[m+8]*rz+a[m+11]);}
  pv[3*v]=x;pv[3*v+1]=y;pv[3*v+2]=z;}}
function draw(){
 const W=cv.width=cv.clientWidth, H=cv.height=cv.clientHeight;
 ctx.fillStyle='#1d1f24';ctx.fillRect(0,0,W,H);
 const j0=3*24*frame; let cx=0,cy=0,cz=0;
 for(const tr of TR){cx+=tr.J[j0]/TR.length;cy+=(tr.J[j0+1]-0.1)/TR.length;cz+=tr.J[j0+2]/TR.length;}
 const cy_=Math.cos(yaw),sy=Math.sin(yaw),cp=Math.cos(pitch),sp=Math.sin(pitch),s=H/dist*1.2;
 function proj(x,y,z){x-=cx;y-=cy;z-=cz;const X=cy_*x-sy*z,Z0=sy*x+cy_*z;const Y=cp*y-sp*Z0,Z=sp*y+cp*Z0;return [W/2+X*s,H/2-Y*s,Z];}
 // floor grid at y=0
 ctx.strokeStyle='#3a3d45';ctx.lineWidth=1;
 for(let i=-5;i<=5;i++){let a=proj(cx+i*0.5,0,cz-2.5),b=proj(cx+i*0.5,0,cz+2.5);ctx.beginPath();ctx.moveTo(a[0],a[1]);ctx.lineTo(b[0],b[1]);ctx.stroke();
  a=proj(cx-2.5,0,cz+i*0.5);b=proj(cx+2.5,0,cz+i*0.5);ctx.beginPath();ctx.moveTo(a[0],a[1]);ctx.lineTo(b[0],b[1]);ctx.stroke();}
 for(const tr of TR){drawTrack(tr,proj);}
 slider.value=frame;document.getElementById('frame').textContent=`${frame+1}/${T}  ${(frame/P.fps).toFixed(2)} s`;
 cv.dataset.frame=frame;}
function drawTrack(tr,proj){
 skin(tr,frame);const J=tr.J,j0=3*24*frame;
 const sv=new Float32Array(V*3);for(let v=0;v<V;v++){const p=proj(pv[3*v],pv[3*v+1],pv[3*v+2]);sv[3*v]=p[0];sv[3*v+1]=p[1];sv[3*v+2]=p[2];}
 if(document.getElementById('mesh').checked){ctx.lineWidth=1;  // the skeleton of a previous track left it at 3
  const depth=new Float32Array(F),order=new Uint32Array(F);
  for(let f=0;f<F;f++){depth[f]=sv[3*faces[3*f]+2]+sv[3*faces[3*f+1]+2]+sv[3*faces[3*f+2]+2];order[f]=f;}
  order.sort((a,b)=>depth[a]-depth[b]);
  for(let i=0;i<F;i++){const f=order[i],a=3*faces[3*f],b=3*faces[3*f+1],c=3*faces[3*f+2];
   const ux=sv[b]-sv[a],uy=sv[b+1]-sv[a+1],vx=sv[c]-sv[a],vy=sv[c+1]-sv[a+1];const cr=ux*vy-uy*vx;if(cr>=0)continue;
   const e1=[pv[b]-pv[a],pv[b+1]-pv[a+1],pv[b+2]-pv[a+2]],e2=[pv[c]-pv[a],pv[c+1]-pv[a+1],pv[c+2]-pv[a+2]];
   const n=[e1[1]*e2[2]-e1[2]*e2[1],e1[2]*e2[0]-e1[0]*e2[2],e1[0]*e2[1]-e1[1]*e2[0]];const nl=Math.hypot(n[0],n[1],n[2])||1;
   const L=0.3+0.7*Math.max(0,(n[0]*0.3+n[1]*0.7+n[2]*0.6)/nl/1.0),tc=tr.col;
   ctx.fillStyle=`rgb(${Math.round(tc[0]*L)},${Math.round(tc[1]*L)},${Math.round(tc[2]*L)})`;ctx.strokeStyle=ctx.fillStyle;
   ctx.beginPath();ctx.moveTo(sv[a],sv[a+1]);ctx.lineTo(sv[b],sv[b+1]);ctx.lineTo(sv[c],sv[c+1]);ctx.closePath();ctx.fill();ctx.stroke();}}
 if(document.getElementById('skel').checked){ctx.strokeStyle='#ff5050';ctx.lineWidth=3;
  for(let j=1;j<24;j++){const p=P.parents[j];const a=proj(J[j0+3*j],J[j0+3*j+1],J[j0+3*j+2]),b=proj(J[j0+3*p],J[j0+3*p+1],J[j0+3*p+2]);
   ctx.beginPath();ctx.moveTo(a[0],a[1]);ctx.lineTo(b[0],b[1]);ctx.stroke();}}
 if(document.getElementById('site').checked){ctx.fillStyle=SITE_COL;ctx.strokeStyle='#222';ctx.lineWidth=1;
  for(const v of P.sites){ctx.beginPath();ctx.arc(sv[3*v],sv[3*v+1],5,0,7);ctx.fill();ctx.stroke();}}
 if(TR.length>1){const h=proj(J[j0+45],J[j0+46]+0.35,J[j0+47]),tc=tr.col;ctx.fillStyle=`rgb(${tc[0]},${tc[1]},${tc[2]})`;ctx.font='bold 14px sans-serif';ctx.textAlign='center';ctx.fillText(tr.label,h[0],h[1]);}}
function tick(now){if(playing){const f=Math.floor((now-t0)*P.fps/1000)%T;if(f!==frame){frame=f;draw();}}requestAnimationFrame(tick);}
draw();requestAnimationFrame(tick);
</script></body></html>
"""
