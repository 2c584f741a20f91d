"""The report page's inline style and script: nothing is fetched, so it works offline.

Kept apart from the writer so the page's look can change without touching how it is
streamed. The script only adds behaviour (the filter box, also set from the link's
``#filter=<text>``, a hover card, the timings a benchmark reads); the page is complete
and drawn without it.
"""

from __future__ import annotations

#: No request of any kind: only the inline style and script run (a CI artifact opened
#: offline, or from a server that must not be asked for anything else).
CONTENT_SECURITY_POLICY = (
    "default-src 'none'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; "
    "img-src 'none'; base-uri 'none'; form-action 'none'"
)

STYLE = """
:root{--pass:#2e7d32;--fail:#c62828;--flaky:#ef8f00;--timeout:#6a1b9a;--skip:#9e9e9e;
--wait:#546e7a;--waitres:#f4511e;--ink:#1d1d1f;--muted:#5f6368;--line:#e3e3e3;--bg:#fafafa}
*{box-sizing:border-box}
body{margin:0;font:14px/1.4 system-ui,-apple-system,"Segoe UI",sans-serif;color:var(--ink);
background:var(--bg)}
main{padding:0 20px 40px;max-width:1600px;margin:0 auto}
header.banner{padding:14px 20px;color:#fff}
header.banner.failed{background:var(--fail)}header.banner.passed{background:var(--pass)}
header.banner h1{margin:0;font-size:22px}
header.banner p{margin:4px 0 0;font-size:15px}
h2{font-size:17px;margin:22px 0 8px;border-bottom:2px solid var(--line);padding-bottom:4px}
.totals{display:flex;gap:10px;flex-wrap:wrap;margin:14px 0}
.total{background:#fff;border:1px solid var(--line);border-radius:6px;padding:6px 12px;
min-width:7em}
.total b{display:block;font-size:20px}
.total.bad b{color:var(--fail)}.total.warn b{color:var(--flaky)}
#split-problems{border:2px solid var(--fail);border-radius:6px;background:#fff;
padding:0 12px;margin:14px 0}#split-problems h2{color:var(--fail)}
table.facts{border-collapse:collapse;background:#fff}
table.facts th,table.facts td{border:1px solid var(--line);padding:3px 8px;text-align:left;
vertical-align:top}
table.facts th{font-weight:600;background:#f3f3f3;white-space:nowrap}
table.facts .differs{color:var(--flaky)}table.facts ul{margin:2px 0;padding-left:18px}
.legend{display:flex;gap:14px;flex-wrap:wrap;font-size:12px;color:var(--muted);margin:4px 0 6px}
.legend i{display:inline-block;width:14px;height:10px;margin-right:4px;vertical-align:-1px;
border-radius:2px}
#timeline{position:relative;background:#fff;border:1px solid var(--line);border-radius:6px;
padding:0 8px 6px 0;overflow:hidden}
.tgrid{position:absolute;top:0;bottom:0;left:170px;right:8px;pointer-events:none}
.tick{position:absolute;top:0;bottom:0;border-left:1px solid #eee}
.tick span{position:absolute;top:3px;left:3px;font-size:11px;color:var(--muted);
white-space:nowrap}
.taxis{height:22px}
.trow{display:flex;border-top:1px solid #f0f0f0;position:relative}
.tlabel{width:170px;flex:none;font:12px/24px ui-monospace,monospace;padding:1px 8px;
white-space:nowrap;overflow:hidden;text-overflow:ellipsis;color:var(--muted)}
.trow.clash .tlabel{color:var(--fail);font-weight:700}
.tlane{position:relative;flex:1;height:calc(var(--lanes) * 26px)}
.bar{position:absolute;top:calc(var(--lane) * 26px + 2px);height:16px;min-width:3px;
border-radius:3px;color:#fff;font:11px/16px system-ui,sans-serif;padding:0 4px;
white-space:nowrap;overflow:hidden;text-overflow:ellipsis;text-decoration:none;z-index:2}
.bar.passed{background:var(--pass)}.bar.failed{background:var(--fail)}
.bar.flaky{background:var(--flaky)}.bar.timeout{background:var(--timeout)}
.bar.skipped{background:var(--skip)}
.bar.narrow{color:transparent;padding:0}
.bar:hover,.bar.hot{outline:2px solid var(--ink);z-index:3}
.bar.dim,.wait.dim{opacity:.15}
/* A wait is drawn under the lane's bars: the bar of the test it waited for stays seen. */
.wait{position:absolute;top:calc(var(--lane) * 26px + 20px);height:4px;z-index:1}
.wait.domain,i.k-wait{background:repeating-linear-gradient(90deg,var(--wait) 0 4px,
transparent 4px 7px)}
.wait.resources,i.k-waitres{background:repeating-linear-gradient(90deg,var(--waitres) 0 4px,
transparent 4px 7px)}
i.k-passed{background:var(--pass)}i.k-failed{background:var(--fail)}
i.k-flaky{background:var(--flaky)}i.k-timeout{background:var(--timeout)}
i.k-skipped{background:var(--skip)}
#card{position:fixed;display:none;z-index:10;background:#fff;border:1px solid #999;
border-radius:6px;padding:6px 10px;box-shadow:0 2px 8px rgba(0,0,0,.2);font-size:12px;
max-width:34em;pointer-events:none;white-space:pre-line}
.filterbar{position:sticky;top:0;background:var(--bg);padding:8px 0;z-index:5}
#filter{width:100%;max-width:40em;font-size:15px;padding:6px 10px;border:1px solid #bbb;
border-radius:6px}
article.case{background:#fff;border:1px solid var(--line);border-left:6px solid var(--fail);
border-radius:4px;margin:8px 0;padding:6px 12px}
article.case.flaky{border-left-color:var(--flaky)}
article.case h3{margin:2px 0;font-size:15px;word-break:break-all}
.tag{display:inline-block;font-size:11px;font-weight:700;color:#fff;border-radius:3px;
padding:0 6px;margin-right:6px;vertical-align:2px;text-transform:uppercase}
.tag.failure,.tag.error{background:var(--fail)}.tag.flaky{background:var(--flaky)}
.tag.timeout{background:var(--timeout)}
.known{display:inline-block;font-size:12px;font-weight:600;border-radius:3px;padding:0 6px;
margin-left:8px;vertical-align:1px;border:1px solid}
.known.new{color:var(--fail);border-color:var(--fail)}
.known.flaky{color:#8a5200;border-color:var(--flaky);background:#fff8e6}
.known.broken{color:#fff;background:#7f1d1d;border-color:#7f1d1d}
.strip{display:inline-flex;gap:1px;margin-left:8px;vertical-align:1px}
.strip i{font:700 10px/14px ui-monospace,monospace;font-style:normal;width:11px;
text-align:center;color:#fff;border-radius:2px;background:var(--skip)}
.strip i.sP{background:var(--pass)}.strip i.sF,.strip i.sE{background:var(--fail)}
.strip i.sf{background:var(--flaky)}.strip i.sT{background:var(--timeout)}
.strip i.now{outline:2px solid var(--ink);outline-offset:1px;margin-left:3px}
.where{color:var(--muted);font-size:12px;word-break:break-all}
pre{background:#f6f6f6;border:1px solid #eee;padding:6px 8px;margin:6px 0;overflow:auto;
max-height:24em;font:12px/1.35 ui-monospace,monospace;white-space:pre-wrap;
word-break:break-all}
pre.message{background:#fff4f4;border-color:#f5c6c6;color:#7a1010;font-weight:600}
article.flaky pre.message{background:#fff8e6;border-color:#f3dca2;color:#6b4a00}
ol.attempts{margin:4px 0;padding-left:1.4em}
details>summary{cursor:pointer}
details.pkg{margin:6px 0;background:#fff;border:1px solid var(--line);border-radius:4px;
padding:4px 10px}
details.pkg>summary{font-weight:700}
details.suite{margin:2px 0 2px 14px;content-visibility:auto;contain-intrinsic-size:auto 24px}
.counts{color:var(--muted);font-size:12px;margin-left:6px}
table.cases{border-collapse:collapse;margin:4px 0 8px 14px;font-size:13px}
table.cases td{padding:1px 10px 1px 0;vertical-align:top;word-break:break-all}
table.cases tr.cls th{text-align:left;font-weight:600;color:var(--muted);padding-top:4px}
tr.c.skipped td:first-child{color:var(--skip)}
td.o{font-size:11px;color:var(--muted)}
.hidden{display:none !important}
.none{color:var(--muted);font-style:italic}
"""

SCRIPT = """
(function(){
'use strict';
var root=document.documentElement;
root.dataset.readyMs=performance.now().toFixed(1);
requestAnimationFrame(function(){setTimeout(function(){
  root.dataset.drawnMs=performance.now().toFixed(1);},0);});
var card=document.getElementById('card');
var timeline=document.getElementById('timeline');
if(timeline&&card){
  timeline.addEventListener('mouseover',function(e){
    var t=e.target.closest('.bar,.wait');if(!t){return;}
    card.textContent=t.getAttribute('data-card')||t.getAttribute('title')||'';
    card.style.display='block';});
  timeline.addEventListener('mousemove',function(e){
    var x=Math.min(e.clientX+14,window.innerWidth-card.offsetWidth-8);
    card.style.left=x+'px';card.style.top=(e.clientY+14)+'px';});
  timeline.addEventListener('mouseout',function(e){
    if(e.target.closest('.bar,.wait')){card.style.display='none';}});
}
var box=document.getElementById('filter');
if(!box){return;}
var pending=0;
function has(el,q){return (el.getAttribute('data-test')||'').toLowerCase().indexOf(q)>=0;}
function textHas(el,q){return el.textContent.toLowerCase().indexOf(q)>=0;}
function apply(){
  var q=box.value.trim().toLowerCase();
  var cases=document.querySelectorAll('article.case');
  for(var i=0;i<cases.length;i++){
    cases[i].classList.toggle('hidden',!!q&&!has(cases[i],q)&&!textHas(cases[i].querySelector('h3'),q));}
  var suites=document.querySelectorAll('details.suite');
  for(var s=0;s<suites.length;s++){
    var suite=suites[s],whole=!q||has(suite,q),any=whole;
    var groups=suite.querySelectorAll('tbody');
    for(var g=0;g<groups.length;g++){
      var group=groups[g];
      var all=whole||(group.getAttribute('data-class')||'').toLowerCase().indexOf(q)>=0;
      var rows=group.querySelectorAll('tr.c'),shown=0;
      for(var r=0;r<rows.length;r++){
        var on=all||textHas(rows[r].firstChild,q);rows[r].classList.toggle('hidden',!on);
        if(on){shown++;}}
      group.classList.toggle('hidden',!shown);if(shown){any=true;}}
    suite.classList.toggle('hidden',!any&&!!q);
    if(q&&any&&!whole){suite.open=true;}}
  var pkgs=document.querySelectorAll('details.pkg');
  for(var p=0;p<pkgs.length;p++){
    pkgs[p].classList.toggle('hidden',!!q&&!pkgs[p].querySelector('details.suite:not(.hidden)'));}
  var bars=document.querySelectorAll('#timeline .bar,#timeline .wait');
  for(var b=0;b<bars.length;b++){bars[b].classList.toggle('dim',!!q&&!has(bars[b],q));}
}
function remember(){
  var q=box.value.trim();
  history.replaceState(null,'',q?'#filter='+encodeURIComponent(q):location.pathname);}
box.addEventListener('input',function(){
  clearTimeout(pending);pending=setTimeout(function(){apply();remember();},150);});
/* A link to the page can carry a filter: report.html#filter=talker */
var linked=/^#filter=(.*)$/.exec(location.hash);
if(linked){box.value=decodeURIComponent(linked[1]);}
if(box.value){apply();}
})();
"""
