#!/usr/bin/python3
"""Checks the structure of the job descriptions dsm-farm writes.

Usage: check_dsm_farm_jobs.py opencue OUTLINE RANGE
       check_dsm_farm_jobs.py openjd TEMPLATE RANGE
The OpenCue outline must parse as Python and hold a "parts" Shell layer over
RANGE whose command has the frame token, a "stitch" layer, and
stitch.depend_all(parts). The OpenJD template must load as YAML with a "parts"
step over an INT parameter with RANGE whose arguments use it, and a "stitch"
step that depends on "parts". Exit status 1 and the reason when not.
"""

import ast
import sys


def fail(why):
    print("FAIL:", why)
    sys.exit(1)


def check_opencue(text, frames):
    tree = ast.parse(text)
    layers = {}
    depends = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        if isinstance(node.func, ast.Name) and node.func.id == "Shell":
            name = ast.literal_eval(node.args[0])
            keywords = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
            layers[name] = keywords
        if isinstance(node.func, ast.Attribute) and node.func.attr == "depend_all":
            depends.append((node.func.value.id, node.args[0].id))
    if set(layers) != {"parts", "stitch"}:
        fail(f"layers {sorted(layers)}, expected parts and stitch")
    if layers["parts"].get("range") != frames:
        fail(f"parts range {layers['parts'].get('range')!r}, expected {frames!r}")
    command = layers["parts"]["command"]
    if "#IFRAME#" not in command or command[command.index("#IFRAME#") - 1] != "--index":
        fail(f"the parts command does not pass the frame as --index: {command}")
    if "stitch" not in layers["stitch"]["command"]:
        fail("the stitch layer does not run dsm-farm stitch")
    if ("stitch", "parts") not in depends:
        fail(f"no stitch.depend_all(parts): {depends}")


def check_openjd(text, frames):
    import yaml

    job = yaml.safe_load(text)
    if job.get("specificationVersion") != "jobtemplate-2023-09":
        fail(f"specificationVersion {job.get('specificationVersion')!r}")
    steps = {step["name"]: step for step in job["steps"]}
    if list(steps) != ["parts", "stitch"]:
        fail(f"steps {list(steps)}, expected parts then stitch")
    (parameter,) = steps["parts"]["parameterSpace"]["taskParameterDefinitions"]
    if parameter["type"] != "INT" or str(parameter["range"]) != frames:
        fail(f"parts parameter {parameter}, expected INT over {frames!r}")
    args = steps["parts"]["script"]["actions"]["onRun"]["args"]
    token = "{{Task.Param." + parameter["name"] + "}}"
    if token not in args or args[args.index(token) - 1] != "--index":
        fail(f"the parts arguments do not pass {token} as --index: {args}")
    if steps["stitch"].get("dependencies") != [{"dependsOn": "parts"}]:
        fail(f"stitch dependencies {steps['stitch'].get('dependencies')}")
    if "stitch" not in steps["stitch"]["script"]["actions"]["onRun"]["args"]:
        fail("the stitch step does not run dsm-farm stitch")


def main():
    kind, path, frames = sys.argv[1:4]
    with open(path, encoding="utf-8") as f:
        text = f.read()
    {"opencue": check_opencue, "openjd": check_openjd}[kind](text, frames)
    print(f"{kind}: {path} is well formed")


main()
