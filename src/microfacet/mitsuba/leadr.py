import mitsuba as mi
PLUGIN = "mf_leadr"
def bsdf_class():
    raise RuntimeError("todo")
