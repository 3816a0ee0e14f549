; Pick-and-place with a mobile manipulator (seed paper, Sec. IV).
;
; Each action is one of realize's action templates. Objects of type `region`
; (and its subtypes) are the task's symbolic parameters; an `item` object named
; like a scene object (scene.objects) is the object the action handles; every
; other argument (sites) is symbolic bookkeeping that realize drops when it maps
; a PDDL action to a template call (realize/tasks/pddl.py).
(define (domain pick-place)
  (:requirements :strips :typing)
  (:types
    region site item - object
    base_region grasp_region place_region - region)
  (:predicates
    (robot-at ?p - site)                          ; the base is parked at a site
    (base-near ?r - base_region ?p - site)        ; parking in ?r puts the base at ?p
    (hand-empty)
    (holding ?c - item)
    (item-at ?c - item ?p - site)
    (grasps ?g - grasp_region ?c - item)           ; ?g holds grasp poses of ?c
    (place-on ?r - place_region ?c - item ?p - site)) ; ?r holds place poses of ?c at ?p

  (:action move_to
    :parameters (?r - base_region ?from - site ?to - site)
    :precondition (and (robot-at ?from) (base-near ?r ?to))
    :effect (and (not (robot-at ?from)) (robot-at ?to)))

  (:action grasp
    :parameters (?g - grasp_region ?c - item ?p - site)
    :precondition (and (hand-empty) (robot-at ?p) (item-at ?c ?p) (grasps ?g ?c))
    :effect (and (not (hand-empty)) (not (item-at ?c ?p)) (holding ?c)))

  (:action place
    :parameters (?r - place_region ?c - item ?p - site)
    :precondition (and (holding ?c) (robot-at ?p) (place-on ?r ?c ?p))
    :effect (and (not (holding ?c)) (hand-empty) (item-at ?c ?p))))
