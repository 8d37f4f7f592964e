"""
The paper's published numbers, as reference data (not results of this code).

Source: Jutharee, Kaewkamnerdpong, Maneewarn, "Joint Reconfiguration after Failure for
Performing Emblematic Gestures in Humanoid Receptionist Robot", Sensors 2023, 23, 9277
(``shared/seeds/002_daba5800341e0f74.txt``).  The paper's absolute scores are not
comparable one to one with ours: its joint limits, d_offset and orientation units are
not given (spec section 5).
"""

PAPER_GESTURES = ('wai', 'bye', 'salute', 'side_invite')


def _row(minimum, time, median, iqr):
    return {'min': minimum, 'time': time, 'median': median, 'iqr': iqr}


# Table 6: per (gesture, failed right-arm joint number) and algorithm: the minimum
# score ("Min. Diff."), the computation time (s), the median score and its IQR, over
# 100 repetitions with the tuned parameter sets of Table 3.
TABLE6 = {
    ('wai', 1): {'ga': _row(49.1402, 0.6566, 69.6643, 11.0471),
                 'bfoa': _row(42.8178, 0.6187, 50.5072, 10.7610),
                 'abc': _row(41.0485, 0.5774, 44.3499, 2.8718)},
    ('wai', 2): {'ga': _row(58.1797, 0.6540, 70.6528, 9.0588),
                 'bfoa': _row(57.1479, 0.5655, 58.4939, 3.4149),
                 'abc': _row(57.1431, 0.5457, 58.1876, 2.1447)},
    ('wai', 3): {'ga': _row(98.6053, 0.6567, 107.8992, 10.9072),
                 'bfoa': _row(93.7746, 0.5258, 93.9123, 3.2764),
                 'abc': _row(93.7706, 0.5617, 93.8543, 1.0137)},
    ('wai', 4): {'ga': _row(18.9686, 0.6536, 45.7340, 15.0691),
                 'bfoa': _row(2.2879, 0.5539, 14.2642, 10.6975),
                 'abc': _row(2.2689, 0.5570, 6.0225, 2.7596)},
    ('wai', 5): {'ga': _row(39.3249, 0.6435, 55.4432, 9.6103),
                 'bfoa': _row(23.1424, 0.5179, 29.7293, 10.5429),
                 'abc': _row(24.2184, 0.5498, 30.7042, 10.7042)},
    ('wai', 6): {'ga': _row(35.2101, 0.6485, 43.5085, 8.2551),
                 'bfoa': _row(32.8321, 0.5077, 36.2486, 12.7388),
                 'abc': _row(33.0264, 0.5456, 35.3097, 9.2949)},
    ('wai', 7): {'ga': _row(19.5293, 0.6496, 39.3058, 14.2708),
                 'bfoa': _row(8.8689, 0.4662, 12.9176, 10.1463),
                 'abc': _row(8.8584, 0.5688, 10.0184, 2.8088)},
    ('bye', 1): {'ga': _row(18.1645, 0.5614, 32.6537, 8.6828),
                 'bfoa': _row(14.5946, 0.5371, 14.9520, 29.3480),
                 'abc': _row(14.5736, 0.5344, 14.8986, 0.4006)},
    ('bye', 2): {'ga': _row(6.0976, 0.5573, 25.6681, 14.0880),
                 'bfoa': _row(3.4758, 0.5088, 9.4605, 16.5519),
                 'abc': _row(3.2491, 0.5413, 5.6970, 3.7215)},
    ('bye', 3): {'ga': _row(41.6956, 0.5581, 53.1471, 13.9760),
                 'bfoa': _row(38.5793, 0.4468, 46.0145, 4.2315),
                 'abc': _row(38.5830, 0.5342, 39.3959, 4.2612)},
    ('bye', 4): {'ga': _row(11.2942, 0.6028, 35.2845, 17.4609),
                 'bfoa': _row(9.5524, 0.5492, 9.9890, 49.1354),
                 'abc': _row(9.5561, 0.5338, 9.7593, 0.9447)},
    ('bye', 5): {'ga': _row(54.8825, 0.6036, 58.8346, 4.7642),
                 'bfoa': _row(52.7563, 0.4211, 53.8811, 1.6746),
                 'abc': _row(52.6081, 0.5304, 53.5293, 2.2006)},
    ('bye', 6): {'ga': _row(31.7665, 0.5477, 44.6053, 10.7182),
                 'bfoa': _row(27.5324, 0.4849, 28.2962, 4.5840),
                 'abc': _row(27.6241, 0.5431, 31.1612, 6.7783)},
    ('bye', 7): {'ga': _row(8.7007, 0.5956, 28.9101, 15.9774),
                 'bfoa': _row(7.8289, 0.4960, 11.0214, 37.2409),
                 'abc': _row(7.8396, 0.5404, 8.9075, 4.0756)},
    ('salute', 1): {'ga': _row(82.3338, 0.5472, 84.8872, 3.4310),
                    'bfoa': _row(82.2325, 0.6137, 82.5707, 31.2031),
                    'abc': _row(82.2782, 0.5369, 82.7736, 0.4377)},
    ('salute', 2): {'ga': _row(37.2962, 0.5469, 48.4423, 9.7109),
                    'bfoa': _row(35.4799, 0.6014, 37.5537, 20.9101),
                    'abc': _row(35.4694, 0.5394, 35.8170, 0.8266)},
    ('salute', 3): {'ga': _row(44.2610, 0.5525, 57.1333, 11.2424),
                    'bfoa': _row(42.0222, 0.5558, 43.1040, 46.4772),
                    'abc': _row(42.0221, 0.5408, 42.3335, 0.7601)},
    ('salute', 4): {'ga': _row(21.5768, 0.6080, 34.7085, 13.3364),
                    'bfoa': _row(18.1860, 0.5824, 22.5206, 54.7482),
                    'abc': _row(18.1818, 0.5389, 18.6810, 1.8249)},
    ('salute', 5): {'ga': _row(28.2134, 0.5476, 38.8455, 10.0302),
                    'bfoa': _row(24.1045, 0.4632, 27.6639, 30.6599),
                    'abc': _row(24.1781, 0.5323, 29.4687, 5.8234)},
    ('salute', 6): {'ga': _row(34.2160, 0.5542, 50.9548, 11.3999),
                    'bfoa': _row(33.0824, 0.5050, 35.3237, 35.8533),
                    'abc': _row(33.2683, 0.5367, 33.8175, 16.5031)},
    ('salute', 7): {'ga': _row(21.3601, 0.5929, 30.4201, 8.2655),
                    'bfoa': _row(17.4007, 0.5125, 17.5952, 21.4105),
                    'abc': _row(17.3955, 0.5364, 17.3971, 0.0105)},
    ('side_invite', 1): {'ga': _row(51.7017, 0.5483, 61.7445, 7.1490),
                         'bfoa': _row(48.8570, 0.5537, 58.0899, 54.1146),
                         'abc': _row(48.8454, 0.5376, 49.1610, 0.5528)},
    ('side_invite', 2): {'ga': _row(8.8991, 0.5464, 19.4553, 10.2574),
                         'bfoa': _row(7.5411, 0.5404, 11.0276, 37.2525),
                         'abc': _row(7.4523, 0.5428, 8.6145, 1.8183)},
    ('side_invite', 3): {'ga': _row(62.9119, 0.5445, 75.5241, 8.7711),
                         'bfoa': _row(57.7096, 0.4627, 58.9446, 20.0700),
                         'abc': _row(57.7082, 0.5331, 57.7507, 0.2847)},
    ('side_invite', 4): {'ga': _row(27.2899, 0.5526, 32.6247, 6.0936),
                         'bfoa': _row(26.7073, 0.5202, 34.6626, 28.3888),
                         'abc': _row(26.7035, 0.5513, 26.7821, 0.3401)},
    ('side_invite', 5): {'ga': _row(32.7265, 0.5671, 47.7179, 8.7698),
                         'bfoa': _row(29.8469, 0.4813, 35.3923, 18.5515),
                         'abc': _row(29.6142, 0.5386, 31.0482, 2.3620)},
    ('side_invite', 6): {'ga': _row(24.1722, 0.5683, 31.1570, 8.5519),
                         'bfoa': _row(23.7687, 0.5164, 28.4278, 42.2346),
                         'abc': _row(23.7868, 0.5481, 26.6748, 4.3452)},
    ('side_invite', 7): {'ga': _row(7.8360, 0.5744, 19.4936, 10.9503),
                         'bfoa': _row(3.5024, 0.5659, 23.3782, 50.3712),
                         'abc': _row(3.4910, 0.5402, 4.4502, 1.5727)},
}


def _stats(minimum, maximum, mean, sd, median, iqr):
    return {'min': minimum, 'max': maximum, 'mean': mean, 'sd': sd, 'median': median,
            'iqr': iqr}


# Table 4: descriptive statistics of the score, joint 2 failed, 100 repetitions, and
# the Kruskal-Wallis H(2) across the three algorithms (p = 0.000 for every gesture).
TABLE4 = {
    'wai': {'ga': _stats(58.1797, 88.1129, 70.7241, 5.9783, 70.6528, 9.0588),
            'bfoa': _stats(57.1479, 139.2824, 64.4391, 16.8914, 58.4939, 3.4149),
            'abc': _stats(57.1431, 83.2653, 59.1699, 3.0858, 58.1876, 2.1447),
            'kruskal_h': 144.539},
    'bye': {'ga': _stats(6.0976, 55.3328, 26.9466, 10.0887, 25.6681, 14.0880),
            'bfoa': _stats(3.4758, 82.5701, 16.8547, 17.9914, 9.4605, 16.5519),
            'abc': _stats(3.2491, 61.4498, 6.8030, 6.6568, 5.6970, 3.7215),
            'kruskal_h': 138.612},
    'salute': {'ga': _stats(37.2962, 64.8065, 48.6495, 6.5060, 48.4423, 9.7109),
               'bfoa': _stats(35.4799, 123.0403, 51.0233, 25.0001, 37.5537, 20.9101),
               'abc': _stats(35.4694, 42.6509, 36.2064, 1.1113, 35.8170, 0.8266),
               'kruskal_h': 133.416},
    'side_invite': {'ga': _stats(8.8991, 34.1130, 19.6917, 6.4367, 19.4553, 10.2574),
                    'bfoa': _stats(7.5411, 124.6998, 27.7533, 28.9818, 11.0276, 37.2525),
                    'abc': _stats(7.4523, 37.3143, 9.3562, 3.3229, 8.6145, 1.8183),
                    'kruskal_h': 97.740},
}

# Table 5: descriptive statistics of the computation time (s), joint 2 failed.
TABLE5 = {
    'wai': {'ga': _stats(0.6120, 0.7307, 0.6635, 0.0316, 0.6531, 0.0202),
            'bfoa': _stats(0.4658, 0.6895, 0.5669, 0.0456, 0.5674, 0.0713),
            'abc': _stats(0.5427, 0.5729, 0.5504, 0.0050, 0.5500, 0.0058),
            'kruskal_h': 192.905},
    'bye': {'ga': _stats(0.5529, 0.6139, 0.5725, 0.0212, 0.5604, 0.0435),
            'bfoa': _stats(0.4291, 0.6526, 0.5256, 0.0371, 0.5215, 0.0478),
            'abc': _stats(0.5290, 0.5550, 0.5365, 0.0045, 0.5356, 0.0037),
            'kruskal_h': 151.510},
    'salute': {'ga': _stats(0.5441, 0.6098, 0.5608, 0.0197, 0.5496, 0.0402),
               'bfoa': _stats(0.4186, 0.6195, 0.5415, 0.0487, 0.5433, 0.0700),
               'abc': _stats(0.5274, 0.5500, 0.5356, 0.0046, 0.5352, 0.0050),
               'kruskal_h': 88.890},
    'side_invite': {'ga': _stats(0.5431, 0.6034, 0.5601, 0.0199, 0.5492, 0.0392),
                    'bfoa': _stats(0.4427, 0.6216, 0.5338, 0.0394, 0.5375, 0.0577),
                    'abc': _stats(0.5261, 0.5501, 0.5356, 0.0053, 0.5344, 0.0077),
                    'kruskal_h': 103.477},
}

# Which of our algorithm keys corresponds to which column of the paper's tables.
PAPER_COLUMN = {'ga-paper': 'ga', 'bfoa-paper': 'bfoa', 'abc-paper': 'abc'}


def paper_table6(gesture, joint_number, algorithm_key):
    """Return the paper's Table 6 entry for one of our algorithm keys, or None."""
    column = PAPER_COLUMN.get(algorithm_key)
    if column is None:
        return None
    return TABLE6.get((gesture, joint_number), {}).get(column)
