import cProfile, pstats, dataclasses, sys, time
from pathlib import Path
from rtreflect.exchange.scene import load_scene
from rtreflect.integrator.renderer import Renderer
scene = load_scene(Path("bench/peer.toml"))
s = sys.argv[1]
s = s if s == "analytic" else int(s)
r = Renderer(dataclasses.replace(scene, image=dataclasses.replace(scene.image, samples=s)))
r.render(threads=1)
t=time.perf_counter(); r.render(threads=1); print("render", time.perf_counter()-t)
pr = cProfile.Profile(); pr.enable(); res = r.render(threads=1); pr.disable()
print(res.stats)
pstats.Stats(pr).sort_stats("tottime").print_stats(25)
