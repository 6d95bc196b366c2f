"""Placeholder main job; replaced by the scene -> node -> bag demonstration."""


def main():
    from rotation_node import conversions as rc
    q = rc.quaternion_from_euler([0.1, 0.2, 0.3], 'xyz')
    print('quaternion_from_euler([0.1, 0.2, 0.3], "xyz") =', q)


if __name__ == '__main__':
    main()
