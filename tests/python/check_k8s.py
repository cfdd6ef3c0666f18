"""Validates the Kubernetes manifests of examples/cluster/kubernetes against the API's schemas
(kubernetes-validate, strict: an unknown field is an error), and checks what the schema cannot:
the sharded Job's FDI_SHARD_COUNT equals its completions and its command asks for
`--shard auto`. A copy with a misspelt field must be refused (the check can fail).

Usage: python check_k8s.py examples/cluster/kubernetes
"""

import copy
import pathlib
import sys

import kubernetes_validate
import yaml

VERSION = "1.33.0"


def validate(doc, name):
    kubernetes_validate.validate(doc, VERSION, strict=True)
    print(f"{name}: {doc['kind']} {doc['metadata']['name']}: valid against Kubernetes {VERSION}")


def check_shards(doc, name):
    spec = doc["spec"]
    if spec.get("completionMode") != "Indexed":
        return False
    container = spec["template"]["spec"]["containers"][0]
    env = {e["name"]: e.get("value") for e in container.get("env", [])}
    count = env.get("FDI_SHARD_COUNT")
    if count != str(spec["completions"]):
        sys.exit(f"{name}: FDI_SHARD_COUNT is {count!r}, the Job's completions {spec['completions']}")
    command = container["command"]
    if "--shard" not in command or command[command.index("--shard") + 1] != "auto":
        sys.exit(f"{name}: the shard's command does not ask for --shard auto: {command}")
    print(f"{name}: {spec['completions']} shards, FDI_SHARD_COUNT agrees")
    return True


def main():
    folder = pathlib.Path(sys.argv[1])
    files = sorted(folder.glob("*.yaml"))
    if not files:
        sys.exit(f"{folder}: no manifest")
    indexed = 0
    for f in files:
        for doc in yaml.safe_load_all(f.read_text()):
            if doc is None:
                continue
            validate(doc, f.name)
            if doc["kind"] == "Job":
                indexed += check_shards(doc, f.name)
                bad = copy.deepcopy(doc)
                bad["spec"]["completionz"] = 1
                try:
                    kubernetes_validate.validate(bad, VERSION, strict=True)
                except kubernetes_validate.ValidationError:
                    pass
                else:
                    sys.exit(f"{f.name}: a misspelt field was not refused: the check checks nothing")
    if indexed != 1:
        sys.exit(f"{folder}: {indexed} Indexed Jobs, expected the sharded one")


if __name__ == "__main__":
    main()
