from glob import glob

from setuptools import find_packages, setup

package_name = 'mechdeconv_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks', 'benchmarks.*', 'tools',
                                    'tools.*']),
    # The glass catalogs (read by mechdeconv_ros/optics/glass.py) travel inside the package for
    # both install routes (pip wheel and colcon's setup.py build); find_packages ships the layer
    # subpackages.
    package_data={package_name: ['data/*.csv']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    # Python libraries only: ROS packages (rclpy, *_msgs, launch_ros, ...) are declared in
    # package.xml (test/test_dependencies.py explains why and checks both lists).
    install_requires=['setuptools', 'numpy', 'opencv-python-headless', 'PyYAML', 'matplotlib',
                      'tqdm'],
    zip_safe=True,
    maintainer='mechdeconv_ros maintainers',
    maintainer_email='maintainers@mechdeconv.invalid',
    description='Calibration-free lens distortion correction for ROS 2 camera streams.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'correct_node = mechdeconv_ros.node.entry:correct_node',
            'stereo_node = mechdeconv_ros.node.entry:stereo_node',
            'mechdeconv = mechdeconv_ros.tools.cli:main',
            'demo_camera = mechdeconv_ros.tools.demo_camera:main',
        ],
    },
)
