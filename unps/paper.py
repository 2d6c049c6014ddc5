"""Figures published by Kaya et al. 2021, to print next to ours."""

# Published normal MAE (degrees) of Kaya et al. 2021: supplementary Table 1 (synthetic subjects,
# preset and resolution of the paper) and the main paper's DiLiGenT table (estimated lights).
PAPER_MAE = {
    "gt": {"Vase": 16.40, "Golf-ball": 14.23, "Face": 14.24, "Tablet1": 10.77, "Tablet2": 4.49,
           "BrokenPot": 15.92},
    "estimated": {"Vase": 19.91, "Golf-ball": 11.04, "Face": 13.43, "Tablet1": 12.37,
                  "Tablet2": 13.12, "BrokenPot": 18.55, "ball": 3.78, "cat": 7.91, "pot1": 8.75},
}

PAPER_FACETS = {"ball": 985, "cat": 2808, "pot1": 3601, "bear": 2585, "pot2": 2193, "buddha": 2787,
                "goblet": 1636, "reading": 1723, "cow": 1651, "harvest": 3582, "Vase": 1280,
                "Golf-ball": 468, "Face": 435, "Tablet1": 1610, "Tablet2": 437, "BrokenPot": 1046}

PAPER_ROSE_MAE = 60.82

PAPER_SPHERE_LIGHT_MAE = 6.31
