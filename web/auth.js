// pendant: the browser login (login.html) and who is logged in on the other pages.
// Plain ES module, no build step. The login trades an API token for an HttpOnly, SameSite=Strict
// session cookie; commands then carry the CSRF token from the readable `pendant_csrf` cookie
// (web/api.js sends it). After the idle timeout the service treats the login as an Operator:
// the badge says so, and a new login restores the user's role.

import { isolate } from "/ui.js";

const POLL_MS = 30_000;

async function post(path, body) {
  const csrf = document.cookie.match(/(?:^|;\s*)pendant_csrf=([^;]*)/);
  const headers = { "Content-Type": "application/json" };
  if (csrf) headers["X-CSRF-Token"] = decodeURIComponent(csrf[1]);
  return fetch(path, { method: "POST", headers, body: JSON.stringify(body ?? {}) });
}

async function login(token) {
  const r = await post("/auth/login", { token });
  if (r.ok) {
    location.replace("/");
    return;
  }
  let msg = `${r.status} ${r.statusText}`;
  try { msg = (await r.json()).detail[0].msg; } catch { /* keep the status */ }
  document.getElementById("login-err").textContent = msg;
}

function loginPage() {
  const form = document.getElementById("login-form");
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    login(form.elements.token.value.trim());
  });
  // the one-time link of the first start: /login.html#token=pdt_...
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    history.replaceState(null, "", location.pathname);  // the token leaves the address bar
    linkLogin(decodeURIComponent(m[1]));
  }
}

// A link logs in whoever opens it: one someone else sent (their own token) silently swapped
// the person's login for theirs. Logged in already, the person is asked first.
async function linkLogin(token) {
  const r = await fetch("/auth/me");
  if (r.ok) {
    const me = await r.json();
    if (!window.confirm(`You are logged in as ${isolate(me.user)} (${me.role}). ` +
                        "Log in with the token of this link instead?")) {
      location.replace("/");
      return;
    }
  }
  login(token);
}

async function badge() {
  const bar = document.querySelector(".topbar");
  if (!bar) return;
  let who = document.getElementById("who");
  const r = await fetch("/auth/me");
  if (r.status === 401) {
    location.assign("/login.html");
    return;
  }
  if (!r.ok) return;
  const me = await r.json();
  if (!who) {
    who = document.createElement("span");
    who.id = "who";
    bar.append(who);
  }
  who.className = me.idle ? "who idle" : "who";
  who.textContent = `${isolate(me.user)} · ${isolate(me.role)}${me.idle ? " (idle: log in again)" : ""}`;
  if (me.source === "pendant") {
    const out = document.createElement("button");
    out.type = "button";
    out.textContent = me.idle ? "Log in" : "Log out";
    out.addEventListener("click", async () => {
      await post("/auth/logout");
      location.assign("/login.html");
    });
    who.append(out);
  }
}

if (document.getElementById("login-form")) {
  loginPage();
} else {
  badge();
  setInterval(badge, POLL_MS);
}
