// SPDX-License-Identifier: Apache-2.0
// The page's device reader (cbp.teleop.device_link): every C.period ms, read
// the gamepad (navigator.getGamepads()) or the 6-DOF mouse (WebHID) and the
// keys held, and send the state as JSON to the session's device link.
//
// C (window.cbpDeviceConfig): port, device, period, button, key (the
// deadman), full (a 6-DOF mouse's full travel), vendors, missing (the status
// line without a device). hid: the 6-DOF mouse's latest state (it reports
// only what changes: report 1 the translation, and on newer models the
// rotation too; report 2 the rotation; report 3 the buttons' bits; unplugged,
// it is forgotten and nothing is sent). keys: the keys held, single letters in
// lower case (none once the page loses focus).
(function(){
if(window.cbpDevice)return;window.cbpDevice=1;
var C=window.cbpDeviceConfig;
var keys=new Set(),hid={axes:[0,0,0,0,0,0],buttons:[],device:null},ws=null,up=false;
function named(e){return e.key.length===1?e.key.toLowerCase():e.key;}
document.addEventListener('keydown',function(e){keys.add(named(e));});
document.addEventListener('keyup',function(e){keys.delete(named(e));});
window.addEventListener('blur',function(){keys.clear();});
function connect(){
 ws=new WebSocket((location.protocol==='https:'?'wss://':'ws://')+location.hostname+':'+C.port+'/');
 ws.onopen=function(){up=true;};
 ws.onclose=function(){up=false;setTimeout(connect,500);};
}
connect();
function say(t){var s=document.getElementById('cbp-device-status');if(s&&s.textContent!==t)s.textContent=t;}
function pad(){
 var ps=navigator.getGamepads?navigator.getGamepads():[];
 for(var i=0;i<ps.length;i++){if(ps[i]&&ps[i].connected)return ps[i];}
 return null;
}
function report(e){
 var v=e.data,n=v.byteLength>>1,i;
 function a(i){return Math.max(-1,Math.min(1,v.getInt16(2*i,true)/C.full));}
 if(e.reportId===1){for(i=0;i<Math.min(n,6);i++)hid.axes[i]=a(i);}
 else if(e.reportId===2){for(i=0;i<Math.min(n,3);i++)hid.axes[3+i]=a(i);}
 else if(e.reportId===3){
  var b=0;for(i=0;i<Math.min(v.byteLength,4);i++)b|=v.getUint8(i)<<(8*i);
  hid.buttons=[];for(i=0;i<32;i++)hid.buttons.push((b>>>i)&1);
 }
}
function gone(e){
 if(e.device!==hid.device)return;
 hid.device=null;hid.axes=[0,0,0,0,0,0];hid.buttons=[];
}
function use(d){
 return (d.opened?Promise.resolve():d.open()).then(function(){
  hid.device=d;d.addEventListener('inputreport',report);
  navigator.hid.removeEventListener('disconnect',gone);
  navigator.hid.addEventListener('disconnect',gone);
 });
}
var filters=C.vendors.map(function(v){return {vendorId:v};});
window.cbpConnectHid=function(){
 if(!navigator.hid){say('6-DOF mouse: this browser has no WebHID (use Chromium)');return;}
 navigator.hid.requestDevice({filters:filters}).then(function(ds){
  if(ds.length)return use(ds[0]);
 }).catch(function(err){say('6-DOF mouse: '+err);});
};
if(C.device==='spacemouse'&&navigator.hid){
 navigator.hid.getDevices().then(function(ds){if(ds.length)use(ds[0]);});
}
setInterval(function(){
 var s=null;
 if(C.device==='gamepad'){
  var p=pad();
  if(p)s={axes:Array.from(p.axes),buttons:Array.from(p.buttons,function(b){return b.value;}),device:p.id};
 }else if(hid.device){
  s={axes:hid.axes.slice(),buttons:hid.buttons.slice(),device:hid.device.productName};
 }
 if(s===null){say(C.missing);return;}
 s.keys=Array.from(keys);
 if(up)ws.send(JSON.stringify(s));
 var held=(C.button!==null&&(s.buttons[C.button]||0)>0.5)||(C.key!==null&&keys.has(C.key));
 say(s.device+(up?'':' (not connected to the session)')+': deadman '+(held?'HELD':'released'));
},C.period);
})();
