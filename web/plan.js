// pendant: the analysis page's "Plan poses" panel (self-contained; analysis.js does the rest).
// POST /plan proposes D-optimal poses for the named effects; "Record from plan" measures them
// on a simulated arm with the first controller's hidden physics (POST /plan/recording) and
// analyses the new recording (the page then shows ?analysis=<id>).

import { ApiError, request } from "/api.js";

const $ = (sel) => document.querySelector(sel);
let plan = null;

function status(text, kind = "") {
  const s = $("#plan-status");
  s.textContent = text;
  s.className = `status ${kind}`;
}

function refusal(err) {
  if (!(err instanceof ApiError) || !Array.isArray(err.detail)) return String(err.message || err);
  return err.detail.map((d) => `${(d.loc || []).filter((x) => x !== "body").join(".")}: ${d.msg}`).join("; ");
}

function row(cells) {
  const tr = document.createElement("tr");
  for (const c of cells) {
    const td = document.createElement("td");
    td.textContent = c;
    tr.append(td);
  }
  return tr;
}

function showPlan(p) {
  const std = $("#plan-std tbody");
  std.replaceChildren(row(["parameter", `predicted std (noise ${p.noise_mm} mm)`]),
    ...p.parameters.map((k) => row([k, Number(p.predicted_std[k]).toPrecision(3)])));
  $("#plan-std").hidden = false;
  const poses = $("#plan-poses tbody");
  poses.replaceChildren(...p.joints_deg.map((q, i) => row([String(i + 1), q.map((v) => v.toFixed(2)).join(", ")])));
  $("#plan-poses-box").hidden = false;
  const left = p.not_identifiable.length ? ` Not identifiable with a ${p.instrument}: ${p.not_identifiable.join(", ")}.` : "";
  status(`${p.n_poses} poses for ${p.parameters.length} parameters.${left}`, "ok");
  $("#plan-record").disabled = p.instrument !== "tracker";
}

async function makePlan() {
  const body = {
    robot: $("#plan-robot").value,
    effects: $("#plan-effects").value.split(/[\s,]+/).filter(Boolean),
    n: Number($("#plan-n").value),
    instrument: $("#plan-instrument").value,
    payload_kg: Number($("#plan-payload").value || 0),
  };
  status("Planning …");
  $("#plan-go").disabled = true;
  try {
    plan = await request("POST", "/plan", { body });
    plan.payload_kg = body.payload_kg;
    showPlan(plan);
  } catch (err) {
    plan = null;
    status(`The plan was refused: ${refusal(err)}`, "err");
  } finally {
    $("#plan-go").disabled = false;
  }
}

async function recordPlan() {
  if (!plan) return;
  status("Recording the planned poses …");
  try {
    const cells = await request("GET", "/controllers");
    const list = Array.isArray(cells) ? cells : (cells.controllers || []);
    const physics = list.length ? await request("GET", `/controllers/${list[0].id}/cell/physics`) : {};
    const rec = await request("POST", "/plan/recording", {
      body: { robot: $("#plan-robot").value, joints_deg: plan.joints_deg, physics, payload_kg: plan.payload_kg },
    });
    status(`Recording ${rec.id} stored (${rec.n_samples} poses); analysing …`);
    let job = await request("POST", `/recordings/${rec.id}/analyze`);  // a job (202)
    while (!["done", "failed", "cancelled"].includes(job.state)) {
      status(`Recording ${rec.id}: analysing, ${Math.round(100 * job.progress)} % …`);
      await new Promise((resolve) => setTimeout(resolve, 300));
      job = await request("GET", job.links.self);
    }
    if (job.state !== "done") {
      const detail = job.error ? job.error.detail.map((d) => d.msg).join("; ") : job.state;
      status(`The analysis of recording ${rec.id} ended ${job.state}: ${detail}`, "err");
      return;
    }
    location.search = `?analysis=${job.result.analysis_id}`;
  } catch (err) {
    status(`Recording from the plan was refused: ${refusal(err)}`, "err");
  }
}

$("#plan-go").addEventListener("click", makePlan);
$("#plan-record").addEventListener("click", recordPlan);
