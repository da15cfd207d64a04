#!/usr/bin/python3
"""The deployment files agree with the code.

    manifests_test.py --server PATH/dynsolid-server --deploy DIR

Parses every YAML under DIR/k8s and DIR/compose.yaml (Debian's
python3-yaml) and checks, naming the file and the item on failure:
- every flag a manifest passes exists in `dynsolid-server --helpfull`;
- container ports match the --listen and --health_listen ports, probes
  use the health-only port and the native gRPC probe, Services target
  named ports that exist;
- selectors match the pod labels (StatefulSet, Services, PDB), the
  StatefulSet's serviceName is a headless Service;
- the volume mounted at --data_dir is the StatefulSet's claim template,
  the TLS files are in the mounted secret;
- the Dockerfile's ENTRYPOINT flags exist and its port is EXPOSEd.
"""
import argparse
import os
import re
import subprocess
import sys

import yaml

problems = []


def check(ok, where, what):
    if not ok:
        problems.append("%s: %s" % (where, what))


def flags_of(args):
    out = {}
    i = 0
    while i < len(args):
        a = args[i]
        if a.startswith("--"):
            if "=" in a:
                k, v = a[2:].split("=", 1)
            elif i + 1 < len(args) and not args[i + 1].startswith("--"):
                k, v = a[2:], args[i + 1]
                i += 1
            else:
                k, v = a[2:], ""
            out[k] = v
        i += 1
    return out


def port_of(address):
    return int(address.rsplit(":", 1)[1])


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--server", required=True)
    p.add_argument("--deploy", required=True)
    a = p.parse_args()
    helpfull = subprocess.run([a.server, "--helpfull"], capture_output=True, text=True)
    known = set(re.findall(r"--([a-z_0-9]+)", helpfull.stdout + helpfull.stderr))
    check("listen" in known and "data_dir" in known, a.server, "--helpfull lists no flags")

    docs = []
    k8s = os.path.join(a.deploy, "k8s")
    for name in sorted(os.listdir(k8s)):
        if name.endswith(".yaml"):
            with open(os.path.join(k8s, name)) as f:
                for d in yaml.safe_load_all(f):
                    if d:
                        docs.append((name, d))
    by_kind = {}
    for name, d in docs:
        by_kind.setdefault(d["kind"], []).append((name, d))

    # Kustomization lists every other file.
    for name, d in by_kind.get("Kustomization", []):
        files = {n for n, _ in docs if n != name}
        check(set(d["resources"]) == files, name, "resources %s != files %s" % (d["resources"], sorted(files)))

    sts_list = by_kind.get("StatefulSet", [])
    check(len(sts_list) == 1, "k8s", "one StatefulSet expected, got %d" % len(sts_list))
    sname, sts = sts_list[0]
    spec = sts["spec"]
    labels = spec["template"]["metadata"]["labels"]
    check(all(labels.get(k) == v for k, v in spec["selector"]["matchLabels"].items()), sname,
          "selector does not match the pod labels")
    c = spec["template"]["spec"]["containers"][0]
    flags = flags_of(c.get("args", []))
    for f in flags:
        check(f in known, sname, "--%s is not a dynsolid-server flag" % f)
    ports = {p["name"]: p["containerPort"] for p in c["ports"]}
    check(ports.get("grpc") == port_of(flags.get("listen", ":0")), sname,
          "port grpc %s != --listen %s" % (ports.get("grpc"), flags.get("listen")))
    check("health_listen" in flags and ports.get("health") == port_of(flags["health_listen"]), sname,
          "port health must match --health_listen")
    for probe in ("readinessProbe", "livenessProbe"):
        pr = c.get(probe, {})
        check("grpc" in pr, sname, "%s must be the native gRPC probe" % probe)
        check(pr.get("grpc", {}).get("port") == ports.get("health"), sname,
              "%s must use the health-only port (the kubelet's gRPC probe cannot speak TLS)" % probe)
        check(pr.get("grpc", {}).get("service", "") == "", sname,
              "%s service must be \"\" (the server's overall health)" % probe)
    mounts = {m["name"]: m["mountPath"] for m in c.get("volumeMounts", [])}
    claims = [t["metadata"]["name"] for t in spec.get("volumeClaimTemplates", [])]
    data_mounts = [n for n, path in mounts.items() if path == flags.get("data_dir")]
    check(len(data_mounts) == 1 and data_mounts[0] in claims, sname,
          "--data_dir %s must be the mount of a volumeClaimTemplate" % flags.get("data_dir"))
    volumes = {v["name"]: v for v in spec["template"]["spec"].get("volumes", [])}
    for f in ("tls_cert", "tls_key"):
        if f in flags:
            mount = [n for n, path in mounts.items() if flags[f].startswith(path.rstrip("/") + "/")]
            check(len(mount) == 1 and "secret" in volumes.get(mount[0], {}), sname,
                  "--%s %s must be in a mounted Secret" % (f, flags[f]))
    res = c.get("resources", {})
    check("requests" in res and "limits" in res, sname, "resources need requests and limits")

    # Replicas: each pod's name is its --replica, --advertise its stable
    # address behind the headless Service, and --peers lists exactly the
    # StatefulSet's pods at those addresses (scaling changes both).
    env = {e["name"]: e for e in c.get("env", [])}
    check(flags.get("replica") == "$(POD_NAME)" and
          env.get("POD_NAME", {}).get("valueFrom", {}).get("fieldRef", {}).get("fieldPath")
          == "metadata.name", sname, "--replica must be the pod's name (downward API)")
    grpc_port = port_of(flags.get("listen", ":0"))
    headless = spec["serviceName"]
    check(flags.get("advertise") == "$(POD_NAME).%s:%d" % (headless, grpc_port), sname,
          "--advertise must be the pod's address behind %s at the gRPC port" % headless)
    want_peers = ["%s-%d=%s-%d.%s:%d" % (sts["metadata"]["name"], i, sts["metadata"]["name"], i,
                                         headless, grpc_port) for i in range(spec["replicas"])]
    check(flags.get("peers", "").split(",") == want_peers, sname,
          "--peers %s must list the %d replicas: %s"
          % (flags.get("peers"), spec["replicas"], ",".join(want_peers)))

    services = {d["metadata"]["name"]: (n, d) for n, d in by_kind.get("Service", [])}
    check(spec["serviceName"] in services, sname, "serviceName %s is no Service" % spec["serviceName"])
    if spec["serviceName"] in services:
        check(services[spec["serviceName"]][1]["spec"].get("clusterIP") == "None", sname,
              "serviceName %s must be headless" % spec["serviceName"])
    check(any(d["spec"].get("clusterIP") != "None" for _, d in services.values()), "k8s",
          "a Service for clients' first call is missing")
    for svc, (n, d) in services.items():
        sel = d["spec"]["selector"]
        check(all(labels.get(k) == v for k, v in sel.items()), n, "%s selects no pod" % svc)
        for p in d["spec"]["ports"]:
            check(p["targetPort"] in ports or p["targetPort"] in ports.values(), n,
                  "%s targets port %s, which the container lacks" % (svc, p["targetPort"]))
    for n, d in by_kind.get("PodDisruptionBudget", []):
        sel = d["spec"]["selector"]["matchLabels"]
        check(all(labels.get(k) == v for k, v in sel.items()), n, "the PDB selects no pod")
    check(bool(by_kind.get("PodDisruptionBudget")), "k8s", "no PodDisruptionBudget")

    # Dockerfile and compose.
    with open(os.path.join(a.deploy, "Dockerfile")) as f:
        dockerfile = f.read()
    entry = re.search(r"^ENTRYPOINT\s+(\[.*\])", dockerfile, re.M)
    check(entry is not None, "Dockerfile", "no ENTRYPOINT")
    if entry:
        args = yaml.safe_load(entry.group(1))[1:]
        eflags = flags_of(args)
        for f in eflags:
            check(f in known, "Dockerfile", "--%s is not a dynsolid-server flag" % f)
        check(re.search(r"^EXPOSE\s+%d\b" % port_of(eflags.get("listen", ":0")), dockerfile, re.M)
              is not None, "Dockerfile", "the --listen port is not EXPOSEd")
        check(re.search(r"^VOLUME\s+%s\b" % re.escape(eflags.get("data_dir", "?")), dockerfile, re.M)
              is not None, "Dockerfile", "--data_dir is not a VOLUME")
        check(eflags.get("listen", "").startswith("0.0.0.0:"), "Dockerfile",
              "inside the container the server listens on all interfaces")
    with open(os.path.join(a.deploy, "compose.yaml")) as f:
        compose = yaml.safe_load(f)
    srv = compose["services"]["server"]
    for f in flags_of(srv.get("command", [])):
        check(f in known, "compose.yaml", "--%s is not a dynsolid-server flag" % f)
    check(any(v.endswith(":/data") for v in srv.get("volumes", [])), "compose.yaml",
          "no volume at /data")
    # The viewer's gateway: flags it takes (clients/web/gateway/main.js), and
    # its --server names the server service at the port the server listens on.
    gateway_flags = {"server", "listen", "proto", "create", "levels", "access_token_file",
                     "tls_cert", "tls_key", "allow_origin"}
    web = compose["services"].get("web")
    check(web is not None, "compose.yaml", "no web service (the viewer's gateway)")
    if web:
        wflags = flags_of(web.get("command", []))
        for f in wflags:
            check(f in gateway_flags, "compose.yaml", "--%s is not a gateway flag" % f)
        server_port = port_of(eflags.get("listen", ":0")) if entry else 0
        check(wflags.get("server") == "server:%d" % server_port, "compose.yaml",
              "the web service's --server %r is not server:%d" % (wflags.get("server"), server_port))
        with open(os.path.join(a.deploy, "Dockerfile.web")) as f:
            web_docker = f.read()
        wentry = re.search(r"^ENTRYPOINT\s+(\[.*\])", web_docker, re.M)
        check(wentry is not None, "Dockerfile.web", "no ENTRYPOINT")
        if wentry:
            wargs = flags_of(yaml.safe_load(wentry.group(1))[2:])
            for f in wargs:
                check(f in gateway_flags, "Dockerfile.web", "--%s is not a gateway flag" % f)
            check(re.search(r"^EXPOSE\s+%d\b" % port_of(wargs.get("listen", ":0")), web_docker, re.M)
                  is not None, "Dockerfile.web", "the gateway's --listen port is not EXPOSEd")

    if problems:
        for p in problems:
            print("FAIL %s" % p)
        sys.exit(1)
    print("deploy files agree with dynsolid-server: %d manifests, %d flags checked" % (
        len(docs), len(flags)))


if __name__ == "__main__":
    main()
