"""LEAN/LEADR mapping: linear (moment) representation of Beckmann lobes, moment MIP maps
of height and normal maps, filtered lookups and pyramid files (thesis Sec. 3.3-3.4, 5.1).

A texel stores the five linear slope moments ``E1..E5 = E[x~], E[y~], E[x~^2], E[y~^2],
E[x~ y~]`` of the uv square's slopes (Eq. 3.5-3.9); they MIP-map by averaging, convolve
by adding (Listing 5.1) and convert to a Beckmann lobe with :func:`from_moments`.
"""
from .files import load_height_map, load_normal_map, pyramid_file, read_pyramid, write_normal_map, write_pyramid
from .heightfield import gaussian_heightfield
from .maps import (base_moments, bake, bake_reference, decode_normal_map, encode_normal_map,
                   height_to_slopes, normal_map_to_moments, normals_to_slopes,
                   slopes_to_moments, slopes_to_normals)
from .mip import downsample_weights, lookup, mip_pyramid, mip_sizes
from .moments import (clean_moments, clean_to_moments, convolve, covariance, from_moments,
                      scale_height, to_moments, transform)
from . import shading
from .downsample import FilteredSurface, base_lobe, downsample_operator, naive_pyramid
from .shading import (MipEnvironment, artificial_micronormal, diffuse_directional, diffuse_sh,
                      env_specular, point_light, sample_grid, sh_add_directional, sh_irradiance,
                      sh_project)

__all__ = ["to_moments", "from_moments", "convolve", "scale_height", "transform", "covariance",
           "clean_moments", "clean_to_moments",
           "height_to_slopes", "slopes_to_normals", "normals_to_slopes", "encode_normal_map",
           "decode_normal_map", "slopes_to_moments", "normal_map_to_moments", "base_moments",
           "bake", "bake_reference",
           "mip_pyramid", "mip_sizes", "downsample_weights", "lookup",
           "read_pyramid", "write_pyramid", "pyramid_file", "load_height_map", "load_normal_map", "write_normal_map",
           "gaussian_heightfield",
           "shading", "point_light", "env_specular", "MipEnvironment", "sample_grid",
           "artificial_micronormal", "sh_project", "sh_add_directional", "sh_irradiance",
           "diffuse_sh", "diffuse_directional",
           "downsample_operator", "base_lobe", "naive_pyramid", "FilteredSurface"]
